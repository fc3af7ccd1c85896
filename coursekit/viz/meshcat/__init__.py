"""3-D scenes in meshcat, exported as self-contained HTML (this package imports nothing heavy).

    server        the meshcat server process: loopback only, dies with this process (MeshcatServer)
    scene         one Visualizer on its own server: camera, background, HTML export (MeshcatScene, shared_scene)
    pusht         PushT in 3-D, rollouts as animations (PushTMeshcat, export_pusht_rollout)
    mujoco_model  any MuJoCo model in meshcat, rollouts as animations (MujocoMeshcat, export_mujoco_rollout)

Import the modules themselves (``from coursekit.viz.meshcat.scene import MeshcatScene``) or the
names from :mod:`coursekit.viz`; ``scene`` pulls meshcat, ``mujoco_model`` pulls mujoco too.
"""
