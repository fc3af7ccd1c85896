"""benchmarks/bench_latency.py: the pixel head's latency is timed on its architecture until its checkpoint ships."""

from __future__ import annotations

import numpy as np
import pytest


def test_the_pixel_architecture_is_the_pixel_routes_policy_and_predicts_a_chunk_from_frames():
    from benchmarks.bench_latency import HEADS, UNTRAINED_FOR_LATENCY, load_head, pixel_architecture
    from benchmarks.bench_pixel_policy import encoder_config

    assert set(UNTRAINED_FOR_LATENCY) <= set(HEADS)
    if load_head("dp-pixels") is not None:
        pytest.skip("a pixel checkpoint exists: bench_latency times it instead")
    policy = pixel_architecture()
    assert policy.config.obs_type == "image" and policy.config.vision == encoder_config()
    obs = {"image": np.zeros((1, 2, 3, 96, 96), np.uint8), "agent_pos": np.full((1, 2, 2), 256.0, np.float32)}
    chunk = policy.predict_chunk(obs, num_inference_steps=2)
    assert chunk.shape == (1, policy.config.horizon, 2) and np.isfinite(chunk).all()


def test_latency_of_the_pixel_architecture_runs_through_the_real_environment():
    from benchmarks.bench_latency import pixel_architecture
    from coursekit.evaluate.latency import chunk_latency_ms

    ms = chunk_latency_ms(pixel_architecture(), "pusht", sampling={"num_inference_steps": 2}, repeats=1)
    assert 0.0 < ms < 60_000.0
