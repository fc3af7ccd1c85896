"""The scrub widgets: each control redraws its figure in place, from the right numbers.

References: the ensembling replay against the defining weighted average of ACT (Sec. IV-A,
w_i = exp(-m i), oldest first) computed directly; the chunk replay against the executor's
contract (a chunk every Ta steps, its rows To-1 ... To-1+Ta-1 executed).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ipywidgets")

from coursekit.viz.scrubbers.ensembling import ensemble_actions, ensemble_scrubber  # noqa: E402
from coursekit.viz.scrubbers.figure import FigureScrubber  # noqa: E402


def test_scrubber_redraws_in_place():
    import ipywidgets as widgets

    seen = []

    def draw(fig, a):
        seen.append(a)
        fig.add_subplot().plot([0, 1], [0, a])

    s = FigureScrubber(draw, {"a": widgets.IntSlider(value=1, min=0, max=5)}, figsize=(2, 2))
    first, image = bytes(s.image.value), s.image
    assert first.startswith(b"\x89PNG") and s.redraws == 1
    s.controls["a"].value = 4
    assert seen == [1, 4] and s.redraws == 2
    assert s.image is image and bytes(s.image.value) != first  # same widget, new picture
    with pytest.raises(ValueError, match="at least one"):
        FigureScrubber(draw, {})


def test_ensemble_replay_is_the_weighted_average_of_act():
    rng = np.random.default_rng(0)
    T, k, Da = 12, 4, 3
    chunks = rng.normal(size=(T, k, Da))
    for m, newest_first in ((0.0, False), (0.3, False), (0.3, True), (2.0, False)):
        got = ensemble_actions(chunks, m, newest_first)
        for t in range(T):
            made = [s for s in range(max(0, t - k + 1), t + 1)]  # oldest first
            preds = np.array([chunks[s, t - s] for s in made])
            order = preds[::-1] if newest_first else preds
            w = np.exp(-m * np.arange(len(order)))
            np.testing.assert_allclose(got[t], (w[:, None] * order).sum(0) / w.sum(), rtol=1e-12, atol=1e-12)
    s = ensemble_scrubber(chunks, joint=1, joint_name="j1", every=2)
    before = bytes(s.image.value)
    s.controls["m"].value = 5.0
    assert s.redraws == 2 and bytes(s.image.value) != before
    with pytest.raises(ValueError, match=r"\(T, k, Da\)"):
        ensemble_actions(chunks[0], 0.1)


@pytest.fixture(scope="module")
def tiny_dp():
    torch = pytest.importorskip("torch")
    from coursekit.experts.pusht_planner import collect_dataset
    from coursekit.policies import make_policy

    torch.manual_seed(0)
    data = collect_dataset(2, seed=0, progress=False)
    policy, _, _ = make_policy("diffusion", data, batch_size=4, seed=0)
    return policy


def test_chunk_replay_follows_the_receding_horizon_contract(tiny_dp):
    from coursekit.viz.scrubbers.chunks import chunk_replay, record_chunk_rollouts

    runs = record_chunk_rollouts(tiny_dp, seed=100_000, n_action_steps=(1, 5), max_steps=12)
    to, tp = tiny_dp.config.n_obs_steps, tiny_dp.config.horizon
    for ta, run in runs.items():
        n = len(run.actions)
        np.testing.assert_array_equal(run.made_at, np.arange(0, n, ta))  # a new chunk every Ta steps
        assert run.chunks.shape == (len(run.made_at), tp, 2)
        for t in range(n):  # the executed action is row To - 1 + (t - t0) of the chunk in use
            c = run.chunk_at(t)
            np.testing.assert_allclose(run.actions[t], run.chunks[c, to - 1 + t - run.made_at[c]], atol=1e-5)
    s = chunk_replay(runs)
    before = bytes(s.image.value)
    s.controls["step"].value = 7
    after_step = bytes(s.image.value)
    s.controls["ta"].value = 1
    assert s.redraws == 3 and len({before, after_step, bytes(s.image.value)}) == 3
    with pytest.raises(ValueError, match="Ta = 99"):
        record_chunk_rollouts(tiny_dp, seed=100_000, n_action_steps=(99,))


def test_cvae_scrubber_decodes_the_chosen_z():
    torch = pytest.importorskip("torch")
    from coursekit.policies.act import ACTConfig, ACTPolicy
    from coursekit.viz.scrubbers.cvae import cvae_scrubber

    torch.manual_seed(0)
    K = 5
    models = {}
    for beta in (0.01, 1.0):
        p = ACTPolicy(ACTConfig(obs_dim=1, action_dim=1, chunk_size=K, hidden_dim=16, ff_dim=32, n_heads=2,
                                n_encoder_layers=1, n_decoder_layers=1, n_vae_encoder_layers=1, latent_dim=3,
                                dropout=0.0, kl_weight=beta))
        p.fit_normalizers({"obs": np.linspace(-1, 1, 8, dtype=np.float32)[:, None]},
                          np.linspace(-1, 1, 8, dtype=np.float32)[:, None])
        models[beta] = p.eval()
    mu = torch.tensor([[0.0, 2.0, 0.0]] * 4)  # dimension 1 carries the information

    s = cvae_scrubber(models, lambda p: (mu, torch.zeros_like(mu)))
    first = bytes(s.image.value)
    s.controls["z"].value = 2.0
    second = bytes(s.image.value)
    s.controls["beta"].value = 0.01
    assert s.redraws == 3 and first != second != bytes(s.image.value)


def test_delay_scrubber_follows_the_delayed_executors():
    from coursekit.viz.scrubbers.delay import delay_scrubber, play_delay

    # d = 0: synchronous and naive async are both plain receding horizon (a chunk every Ta = 4)
    sync0, sw0 = play_delay("synchronous", 0, steps=12)
    async0, _ = play_delay("naive async", 0, steps=12)
    np.testing.assert_array_equal(sync0, async0)
    assert sw0 == [0, 4, 8]
    # chunk k, planned from the position p the robot is at, says p + (j + 1)(1 +- 0.25), the speed
    # alternating: chunk 0 plays 1.25 .. 5.0; at d = 2 the synchronous robot holds 5.0 for two steps and
    # plays chunk 1 (speed 0.75, planned from 5.0) from its start: it loses time and never jumps
    sync2, sw_sync = play_delay("synchronous", 2, steps=12)
    np.testing.assert_allclose(sync2, [1.25, 2.5, 3.75, 5.0, 5.0, 5.0, 5.75, 6.5, 7.25, 8.0, 8.0, 8.0])
    assert sw_sync == [0, 6]
    # naive async keeps moving on chunk 0 (6.25, 7.5); chunk 1, requested at step 4 from 5.0, takes
    # over at step 6 with its index 2, 5 + 3 * 0.75 = 7.25: a step back; chunk 2 (from 8.0, speed 1.25)
    # at step 10 with its index 2, 8 + 3 * 1.25 = 11.75: a step of 2.25 where a step is 0.75
    async2, sw_async = play_delay("naive async", 2, steps=11)
    np.testing.assert_allclose(async2, [1.25, 2.5, 3.75, 5.0, 6.25, 7.5, 7.25, 8.0, 8.75, 9.5, 11.75])
    assert sw_async == [0, 6, 10]
    for d in range(9):  # whatever d, the synchronous robot's largest step is its fast chunk's own, 1.25
        assert np.abs(np.diff(np.r_[0.0, play_delay("synchronous", d)[0]])).max() == pytest.approx(1.25)
    # once 2 d >= Tp = 12 a chunk has run out when the next one arrives: the ensemble averages one
    # chunk at a time and plays exactly what naive async plays (chapter 11 says so); not before
    for d in (6, 8):
        np.testing.assert_array_equal(play_delay("ensemble", d)[0], play_delay("naive async", d)[0])
    assert not np.allclose(play_delay("ensemble", 5)[0], play_delay("naive async", 5)[0])
    s = delay_scrubber(max_delay=6)
    first = bytes(s.image.value)
    s.controls["d"].value = 5
    assert s.redraws == 2 and bytes(s.image.value) != first
    with pytest.raises(ValueError, match="strategy"):
        play_delay("rtc", 1)


HEADLESS_CELLS = {
    "scrubber": ("import ipywidgets as widgets\nfrom coursekit.viz import FigureScrubber\n"
                 "s = FigureScrubber(lambda fig, a: fig.add_subplot().plot([0, a]), {'a': widgets.IntSlider(value=1)})\n"
                 "s.controls['a'].value = 3\ns"),
    # the pattern chapter 4 used before: an Output that captures display(fig)
    "output capture": ("import ipywidgets as widgets\nfrom IPython.display import display\nfrom matplotlib.figure import Figure\n"
                       "out = widgets.Output()\nfig = Figure()\nfig.add_subplot().plot([0, 1])\n"
                       "with out:\n    out.clear_output(wait=True)\n    display(fig)\nout"),
}


@pytest.mark.notebook
def test_widget_figures_never_make_a_headless_client_write_back():
    """Chapter 4's stall (issue 22). nbclient answers a display captured by an ``ipywidgets.Output``
    with a ``comm_msg`` on the shell channel (its Output-widget mimic syncing the outputs back), sent
    through jupyter_client's ``Session.send`` on a blocking shadow of the asyncio socket. That send
    consumes the socket's edge-triggered wake-up: if the cell's ``execute_reply`` is already queued
    (a busy machine: the kernel finishes before the client has handled the display), the client's
    pending poll is never woken and it waits out its whole cell timeout. The course's widget figures
    (``FigureScrubber``) only set image bytes from the kernel: the client never writes back. The
    Output cell shows that this instrument sees the write-back when it happens."""
    import nbformat
    from nbclient import NotebookClient

    sent: dict[str, list[str]] = {}

    class Recording(NotebookClient):
        async def async_start_new_kernel_client(self):
            kc = await super().async_start_new_kernel_client()
            send = kc.shell_channel.send

            def recording_send(msg):
                sent.setdefault(self.current, []).append(msg["msg_type"])
                return send(msg)

            kc.shell_channel.send = recording_send
            return kc

        async def async_execute_cell(self, cell, cell_index, *args, **kwargs):
            self.current = cell.metadata["name"]
            return await super().async_execute_cell(cell, cell_index, *args, **kwargs)

    cells = [nbformat.v4.new_code_cell(src, metadata={"name": name}) for name, src in HEADLESS_CELLS.items()]
    nb = nbformat.v4.new_notebook(cells=cells)
    # The Output cell can hit the very stall (the client then wakes at its timeout and goes on, no
    # error): a short timeout bounds that cost; the cell itself takes well under a second.
    client = Recording(nb, kernel_name="coursekit",
                       timeout_func=lambda cell: 60 if cell.metadata["name"] == "output capture" else 600)
    client.current = "start"
    client.execute()
    errors = [o for c in nb.cells for o in c.outputs if o.output_type == "error"]
    assert not errors, [e.evalue for e in errors]
    assert sent["scrubber"] == ["execute_request"], f"the scrubber cell made the client send {sent['scrubber']}"
    assert "comm_msg" in sent["output capture"], sent["output capture"]
