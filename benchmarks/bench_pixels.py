"""From pixels on a CPU (chapter 12): where a pixel policy's training time goes on this machine.

Diffusion Policy's image recipe (Chi et al. 2023: a ResNet-18 with GroupNorm and a spatial softmax
per camera, random 84x84 crops of 96x96 frames, To = 2 frames per sample) is a GPU recipe. Before
choosing a design that trains here, this benchmark measures, on one torch thread:

- ``render``: PushT steps per second with pixel observations (96x96, physics + drawing) against
  state observations (physics only): what rendering frames on the fly costs, versus caching them.
- ``encoder``: images per second through one encoder, forward + backward + AdamW step, batch 64,
  for the paper's widths (``resnet18``: 64/128/256/512), the course's ``cpu`` preset (32/.../256)
  and narrower or lower-resolution variants.
- ``policy``: samples per second of a whole Diffusion Policy training step on ``pusht_image``
  features (To = 2 frames through the encoder, then the U-Net's epsilon loss), and the encoder's
  share of it (its forward, and backward when trained, timed alone): for the ``cpu`` encoder and
  the ``small`` one of the two-stage route, trained end to end or frozen (:data:`POLICIES`).

Rows go to "Pixels (PushT): training throughput" with the 1-minute load average in each note (run
it on an idle machine: these are speeds, and a busy core halves them)::

    .venv/bin/python -m benchmarks.bench_pixels            # about 3 minutes
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from benchmarks import results

COMMAND = ".venv/bin/python -m benchmarks.bench_pixels"
SECTION = "Pixels (PushT): training throughput"
ENCODERS = {  # label -> VisionEncoderConfig fields
    "resnet18 widths 64-512, 84x84 crops": {"widths": (64, 128, 256, 512)},
    "cpu preset 32-256, 84x84 crops": {},
    "narrow 16-128, 84x84 crops": {"widths": (16, 32, 64, 128)},
    "narrow 16-128, one block per stage, 56x56 crops of 64x64": {"widths": (16, 32, 64, 128), "blocks_per_stage": 1,
                                                                 "image_size": (64, 64), "crop_size": (56, 56)},
}


def _load_note(extra: str = "") -> str:
    return f"1 torch thread, 1-min load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores{extra}"


def _rate(fn, n: int, warmup: int = 1) -> float:
    """Calls of ``fn`` per second over ``n`` timed calls after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def part_render(args, record) -> None:
    import gymnasium as gym

    import coursekit.envs  # noqa: F401  (registers coursekit/PushT-v0)

    rates = {}
    for obs_type in ("state", "pixels_agent_pos"):
        env = gym.make("coursekit/PushT-v0", obs_type=obs_type)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        rates[obs_type] = _rate(lambda e=env: e.step(rng.uniform(100, 400, size=2)), args.steps)
        env.close()
    per_frame_ms = 1000 * (1 / rates["pixels_agent_pos"] - 1 / rates["state"])
    print(f"PushT steps/s: state {rates['state']:.0f}, 96x96 pixels {rates['pixels_agent_pos']:.0f} "
          f"(drawing a frame: {per_frame_ms:.2f} ms)")
    for obs_type, label in (("state", "state observations"), ("pixels_agent_pos", "96x96 pixel observations")):
        record(SECTION, f"PushT env steps per second, {label}", round(rates[obs_type]), "steps/s",
               f"{COMMAND} --only render", note=_load_note(f"; {args.steps} random-target steps after reset(seed=0)"))


def part_encoder(args, record) -> None:
    import torch

    from coursekit.nn.vision import VisionEncoder, VisionEncoderConfig

    for label, fields in ENCODERS.items():
        cfg = VisionEncoderConfig(**fields)
        torch.manual_seed(0)
        enc = VisionEncoder(cfg).train()
        opt = torch.optim.AdamW(enc.parameters(), lr=1e-4)
        images = torch.rand(args.batch, 3, *cfg.image_size) * 2 - 1  # (B, 3, H, W) in [-1, 1]

        def step():
            opt.zero_grad()
            enc(images).square().mean().backward()
            opt.step()

        per_s = args.batch * _rate(step, args.repeats)
        params = sum(p.numel() for p in enc.parameters()) / 1e6
        print(f"encoder {label}: {per_s:.0f} images/s ({params:.2f} M parameters)")
        record(SECTION, f"encoder {label}: images per second (forward + backward + step)", round(per_s), "images/s",
               f"{COMMAND} --only encoder", note=_load_note(f"; batch {args.batch}, {params:.2f} M parameters"))


POLICIES = {  # label -> (VisionEncoderConfig preset, encoder trained by the loss?)
    "cpu encoder": ("cpu", True),
    "small encoder, end to end": ("small", True),
    "small encoder frozen (two-stage route, stage 2)": ("small", False),
}


def _image_policy(n_demos: int, batch: int, preset: str):
    from coursekit.experts.pusht_planner import collect_dataset
    from coursekit.nn.vision import VisionEncoderConfig
    from coursekit.policies import make_policy

    data = collect_dataset(n_demos, seed=0, progress=False)
    return make_policy("diffusion", data, features="pusht_image", recipe="cpu", batch_size=batch,
                       vision=VisionEncoderConfig.preset(preset))


def part_policy(args, record) -> None:
    """Samples/s of a whole training step, and the encoder's share of it (the rest is the U-Net's)."""
    import torch

    for label, (preset, trained) in POLICIES.items():
        setup = _image_policy(args.demos, args.batch, preset)
        policy, batch = setup.policy, next(iter(setup.batches))
        policy.vision_encoder.requires_grad_(trained)  # frozen: stage 2 of the two-stage route
        opt = torch.optim.AdamW([p for p in policy.parameters() if p.requires_grad], lr=1e-4)
        obs = {k: torch.as_tensor(batch[k]) for k in ("image", "agent_pos")}  # (B, To, ...)

        def step():
            opt.zero_grad()
            policy.compute_loss(batch)["loss"].backward()
            opt.step()

        def encode():  # the encoder's part of a step: forward, and backward when it is trained
            with torch.set_grad_enabled(trained):
                cond = policy.encode_obs(obs)  # (B, To*(F+Dp))
            if trained:
                cond.sum().backward()

        steps_s = _rate(step, args.repeats)
        per_s, share = args.batch * steps_s, min(1.0, steps_s / _rate(encode, args.repeats))  # t_encode / t_step
        print(f"Diffusion Policy on pusht_image ({label}, To = 2 frames): {per_s:.0f} samples/s, "
              f"encoder {100 * share:.0f} % of a step")
        note = _load_note(f"; batch {args.batch} samples of To = 2 frames each (frames rendered once, not per step), "
                          f"encoder preset {preset}{'' if trained else ' frozen'}, U-Net preset cpu, {args.demos} demos")
        record(SECTION, f"Diffusion Policy training step on pusht_image, {label}: samples per second", round(per_s),
               "samples/s", f"{COMMAND} --only policy", note=note)
        record(SECTION, f"Diffusion Policy training step on pusht_image, {label}: encoder share of the step",
               round(100 * share), "%", f"{COMMAND} --only policy", note=note + "; the rest is the U-Net's loss and step")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["render", "encoder", "policy"], default=None, help="run one part")
    parser.add_argument("--steps", type=int, default=2000, help="render: env steps timed per observation type")
    parser.add_argument("--batch", type=int, default=64, help="encoder / policy: batch size")
    parser.add_argument("--repeats", type=int, default=5, help="encoder / policy: timed steps")
    parser.add_argument("--demos", type=int, default=4, help="policy: demonstrations rendered for the batch")
    parser.add_argument("--no-record", action="store_true", help="print only: results.json untouched")
    args = parser.parse_args(argv)
    if min(args.steps, args.batch, args.repeats, args.demos) < 1:
        raise SystemExit(f"--steps/--batch/--repeats/--demos must be >= 1, got {args.steps}/{args.batch}/"
                         f"{args.repeats}/{args.demos}")
    import torch

    torch.set_num_threads(1)
    record = (lambda *a, **k: None) if args.no_record else results.record
    for name, part in (("render", part_render), ("encoder", part_encoder), ("policy", part_policy)):
        if args.only in (None, name):
            part(args, record)


if __name__ == "__main__":
    main()
