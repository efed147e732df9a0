"""How the student's flat observation splits into Transformer tokens.

The deployable observation (deploy/observations.py terms, in obs_spec order) holds proprioception/object terms and
reference terms `ref_*`, each a stack of one block per keyframe (K = {1, 2, 4, 16}: block k covers keyframe k).
Token 0 gathers every non-reference entry; token 1 + k gathers block k of every reference term, so all keyframe
tokens have the same width and the same meaning per position.
"""

from __future__ import annotations

from dataclasses import dataclass

from robot_hoi.errors import UserError

REFERENCE_PREFIX = "ref_"


@dataclass(frozen=True)
class TokenLayout:
    obs_dim: int
    state_index: tuple[int, ...]  # flat indices of token 0 (proprioception + object + anything non-reference)
    keyframe_index: tuple[tuple[int, ...], ...]  # (K, F) flat indices of each keyframe token
    keyframes: tuple[int, ...]

    @property
    def num_keyframes(self) -> int:
        return len(self.keyframe_index)

    @property
    def keyframe_width(self) -> int:
        return len(self.keyframe_index[0]) if self.keyframe_index else 0

    def to_dict(self) -> dict:
        return {"obs_dim": self.obs_dim, "state_index": list(self.state_index),
                "keyframe_index": [list(k) for k in self.keyframe_index], "keyframes": list(self.keyframes)}

    @classmethod
    def from_dict(cls, data: dict) -> TokenLayout:
        return cls(int(data["obs_dim"]), tuple(int(i) for i in data["state_index"]),
                   tuple(tuple(int(i) for i in k) for k in data["keyframe_index"]),
                   tuple(int(k) for k in data["keyframes"]))


def token_layout(obs_spec: list[dict], keyframes: tuple[int, ...] | list[int]) -> TokenLayout:
    """Token index sets for an observation spec [{"name", "size"}, ...] with `keyframes` stacked per ref term."""
    num_k = len(keyframes)
    state: list[int] = []
    per_keyframe: list[list[int]] = [[] for _ in range(num_k)]
    offset = 0
    for term in obs_spec:
        name, size = str(term["name"]), int(term["size"])
        if size <= 0:
            raise UserError(f"observation term {name!r} has size {size}")
        if name.startswith(REFERENCE_PREFIX):
            if num_k == 0 or size % num_k:
                raise UserError(f"reference term {name!r} of size {size} does not split into {num_k} keyframes")
            block = size // num_k
            for k in range(num_k):
                start = offset + k * block
                per_keyframe[k].extend(range(start, start + block))
        else:
            state.extend(range(offset, offset + size))
        offset += size
    if not state:
        raise UserError("the student observation has no proprioception terms")
    keyframe_index = tuple(tuple(k) for k in per_keyframe) if per_keyframe and per_keyframe[0] else ()
    return TokenLayout(offset, tuple(state), keyframe_index, tuple(int(k) for k in keyframes) if keyframe_index
                       else ())
