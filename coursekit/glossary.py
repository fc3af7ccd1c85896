"""One glossary of symbols, used by code, notebooks and docs alike.

The papers' symbols on the left; the names used in configs and code on the right. Notebooks
print ``GLOSSARY`` so that a symbol in the text can always be found in the code.
"""

from __future__ import annotations

GLOSSARY: dict[str, tuple[str, str]] = {
    "To": ("n_obs_steps", "observation steps the policy conditions on (Diffusion Policy: 2)"),
    "Tp": ("horizon", "actions predicted per chunk by Diffusion Policy (16)"),
    "Ta": ("n_action_steps", "actions executed from each chunk before re-planning (8)"),
    "k": ("chunk_size", "actions predicted per chunk by ACT (100)"),
    "beta": ("kl_weight", "weight of the KL term in ACT's CVAE loss (10)"),
    "T": ("num_train_timesteps", "diffusion steps of the forward process (100)"),
    "m": ("ensemble_decay", "temporal-ensembling weight decay, w_i = exp(-m i) (0.01)"),
    "Da": ("action_dim", "dimension of one action (PushT 2, ALOHA 14)"),
    "Do": ("obs_dim", "dimension of one low-dim observation (PushT state 5 -> 6 features)"),
    "N": ("num_inference_steps", "sampler steps per chunk: DDIM denoising or flow-matching Euler steps (10)"),
    "d": ("delay", "inference delay in control steps, d = ceil(chunk latency / control period) (chapter 11)"),
}


def table() -> str:
    """The glossary as a Markdown table."""
    rows = ["| symbol | name in code | meaning |", "|---|---|---|"]
    rows += [f"| {s} | `{name}` | {meaning} |" for s, (name, meaning) in GLOSSARY.items()]
    return "\n".join(rows)


def show() -> None:
    """Print the glossary (for notebooks)."""
    width = max(len(n) for n, _ in GLOSSARY.values())
    for symbol, (name, meaning) in GLOSSARY.items():
        print(f"{symbol:>5} = {name:<{width}}  {meaning}")
