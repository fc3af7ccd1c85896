"""Scrub instead of re-running cells: each chapter's sliders that redraw one figure in place.

    figure       the mechanism: controls + one matplotlib figure redrawn in place (FigureScrubber)
    chunks       chapter 5: Ta / Tp on a recorded PushT rollout (record_chunk_rollouts, chunk_replay)
    cvae         chapter 7: beta and the latent z of the CVAE, the decoded chunk (cvae_scrubber)
    ensembling   chapter 8: temporal ensembling's weight m on a recorded chunk stream (ensemble_scrubber)
    delay        chapter 11: the inference delay d on chunks that disagree (delay_scrubber)

Widgets need a live kernel; in a static render the first picture shows.
"""
