"""ACT's transformer: DETR-style post-norm encoder and decoder stacks, readable layer by layer.

ACT (Zhao et al. 2023, Sec. IV-C and its ``detr/`` code) builds on DETR (Carion et al. 2020):

- Post-norm layers (``normalize_before=False``): x = LayerNorm(x + Sublayer(x)).
- Positions are NOT added to the input once; they are added to the queries and keys of every
  attention (``q = k = x + pos``, values without positions), in every layer.
- The decoder starts from zeros and receives its k learned "object queries" as the query
  position embedding (DETR's ``tgt = zeros_like(query_embed)``), so the queries act only
  through attention, layer after layer.
- The decoder stack ends with a LayerNorm (DETR's ``decoder_norm``); the encoder does not.

Deliberate departure from the original code: ACT's ``Transformer`` computes every decoder layer
but its caller keeps only the FIRST layer's output (``hs[0]`` of the intermediate outputs),
so layers 2..7 are dead weight (LeRobot keeps a single decoder layer to match). We use the
output of the FULL decoder stack, which is what the paper describes.

Shapes: batch-first throughout, tokens (B, S, D), D = hidden_dim.
"""

from __future__ import annotations

import torch
from torch import nn


def _with_pos(x: torch.Tensor, pos: torch.Tensor | None) -> torch.Tensor:
    """x + pos, where pos is (S, D) or (B, S, D) and broadcasts over the batch."""
    return x if pos is None else x + pos


class FeedForward(nn.Module):
    """Linear -> ReLU -> dropout -> Linear (DETR's FFN with ReLU): (B, S, D) -> (B, S, D)."""

    def __init__(self, dim: int, ff_dim: int, dropout: float) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(dim, ff_dim), nn.ReLU(), nn.Dropout(dropout), nn.Linear(ff_dim, dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class EncoderLayer(nn.Module):
    """Post-norm self-attention layer with positions on queries and keys: (B, S, D) -> (B, S, D)."""

    def __init__(self, dim: int, n_heads: int, ff_dim: int, dropout: float) -> None:
        super().__init__()
        self.self_attn = nn.MultiheadAttention(dim, n_heads, dropout=dropout, batch_first=True)
        self.ff = FeedForward(dim, ff_dim, dropout)
        self.norm1, self.norm2 = nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.drop1, self.drop2 = nn.Dropout(dropout), nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, pos: torch.Tensor | None = None,
                key_padding_mask: torch.Tensor | None = None) -> torch.Tensor:
        """x (B, S, D); pos (S, D) or (B, S, D); key_padding_mask (B, S) bool, True = ignore that token."""
        q = k = _with_pos(x, pos)
        attn = self.self_attn(q, k, x, key_padding_mask=key_padding_mask, need_weights=False)[0]
        x = self.norm1(x + self.drop1(attn))
        return self.norm2(x + self.drop2(self.ff(x)))


class DecoderLayer(nn.Module):
    """Post-norm self-attention, cross-attention to the encoder memory, feed-forward.

    tgt (B, k, D) with query_pos (k, D); memory (B, S, D) with memory_pos (S, D) or (B, S, D).
    """

    def __init__(self, dim: int, n_heads: int, ff_dim: int, dropout: float) -> None:
        super().__init__()
        self.self_attn = nn.MultiheadAttention(dim, n_heads, dropout=dropout, batch_first=True)
        self.cross_attn = nn.MultiheadAttention(dim, n_heads, dropout=dropout, batch_first=True)
        self.ff = FeedForward(dim, ff_dim, dropout)
        self.norm1, self.norm2, self.norm3 = nn.LayerNorm(dim), nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.drop1, self.drop2, self.drop3 = nn.Dropout(dropout), nn.Dropout(dropout), nn.Dropout(dropout)

    def forward(self, tgt: torch.Tensor, memory: torch.Tensor, query_pos: torch.Tensor | None = None,
                memory_pos: torch.Tensor | None = None) -> torch.Tensor:
        q = k = _with_pos(tgt, query_pos)
        tgt = self.norm1(tgt + self.drop1(self.self_attn(q, k, tgt, need_weights=False)[0]))
        attn = self.cross_attn(_with_pos(tgt, query_pos), _with_pos(memory, memory_pos), memory, need_weights=False)[0]
        tgt = self.norm2(tgt + self.drop2(attn))
        return self.norm3(tgt + self.drop3(self.ff(tgt)))


class TransformerEncoder(nn.Module):
    """A stack of post-norm encoder layers (no final norm, as in DETR post-norm): (B, S, D) -> (B, S, D)."""

    def __init__(self, n_layers: int, dim: int, n_heads: int, ff_dim: int, dropout: float) -> None:
        super().__init__()
        self.layers = nn.ModuleList(EncoderLayer(dim, n_heads, ff_dim, dropout) for _ in range(n_layers))

    def forward(self, x: torch.Tensor, pos: torch.Tensor | None = None,
                key_padding_mask: torch.Tensor | None = None) -> torch.Tensor:
        for layer in self.layers:
            x = layer(x, pos, key_padding_mask)
        return x


class TransformerDecoder(nn.Module):
    """A stack of post-norm decoder layers and a final LayerNorm; ALL layers are used (see module doc)."""

    def __init__(self, n_layers: int, dim: int, n_heads: int, ff_dim: int, dropout: float) -> None:
        super().__init__()
        self.layers = nn.ModuleList(DecoderLayer(dim, n_heads, ff_dim, dropout) for _ in range(n_layers))
        self.norm = nn.LayerNorm(dim)

    def forward(self, tgt: torch.Tensor, memory: torch.Tensor, query_pos: torch.Tensor | None = None,
                memory_pos: torch.Tensor | None = None) -> torch.Tensor:
        for layer in self.layers:
            tgt = layer(tgt, memory, query_pos, memory_pos)
        return self.norm(tgt)


class ACTTransformer(nn.Module):
    """Encoder over the conditioning tokens, decoder from k learned queries: (B, S, D) -> (B, k, D).

    Args:
        dim: hidden size D.
        n_heads, ff_dim, dropout: per-layer attention heads, feed-forward width, dropout.
        n_encoder_layers, n_decoder_layers: depth of each stack.
        n_queries: k, the chunk size (one learned query per predicted action).
    """

    def __init__(self, dim: int, n_heads: int, ff_dim: int, n_encoder_layers: int, n_decoder_layers: int,
                 n_queries: int, dropout: float) -> None:
        super().__init__()
        if dim % n_heads:
            raise ValueError(f"hidden size {dim} must be divisible by n_heads={n_heads}")
        self.encoder = TransformerEncoder(n_encoder_layers, dim, n_heads, ff_dim, dropout)
        self.decoder = TransformerDecoder(n_decoder_layers, dim, n_heads, ff_dim, dropout)
        self.query_embed = nn.Embedding(n_queries, dim)  # k learned queries (DETR "object queries")
        self._reset_parameters()

    def _reset_parameters(self) -> None:
        # DETR/ACT initialise every matrix of the transformer with Xavier-uniform.
        for p in list(self.encoder.parameters()) + list(self.decoder.parameters()):
            if p.dim() > 1:
                nn.init.xavier_uniform_(p)

    def forward(self, src: torch.Tensor, src_pos: torch.Tensor) -> torch.Tensor:
        """src (B, S, D) conditioning tokens, src_pos (S, D) or (B, S, D) -> (B, k, D) decoder output."""
        memory = self.encoder(src, src_pos)  # (B, S, D)
        query_pos = self.query_embed.weight  # (k, D)
        tgt = torch.zeros(src.shape[0], *query_pos.shape, dtype=src.dtype, device=src.device)  # (B, k, D)
        return self.decoder(tgt, memory, query_pos, src_pos)  # (B, k, D)
