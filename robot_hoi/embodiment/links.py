"""Name lookups on a compiled model: link_map entries -> body or site ids, resolved once.

A link_map key is a body name (position = data.xpos[id], orientation = data.xquat[id]) or a site name
(position = data.site_xpos[id]). Sites are used where the tracked point is not a body origin: toes, head top,
fingertips.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

import mujoco
import numpy as np

from robot_hoi.errors import UserError


@dataclass(frozen=True)
class LinkRef:
    name: str
    kind: Literal["body", "site"]
    id: int


def body_names(model: mujoco.MjModel) -> list[str]:
    """Body names in model order (index 0 is the world)."""
    return [model.body(i).name for i in range(model.nbody)]


def resolve_links(model: mujoco.MjModel, names: Iterable[str]) -> dict[str, LinkRef]:
    """name -> LinkRef, bodies first, then sites; UserError for a name that is neither."""
    out: dict[str, LinkRef] = {}
    for name in names:
        body_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if body_id >= 0:
            out[name] = LinkRef(name, "body", body_id)
            continue
        site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if site_id >= 0:
            out[name] = LinkRef(name, "site", site_id)
            continue
        raise UserError(f"link {name!r} is neither a body nor a site of the model")
    return out


def resolve_link_map(model: mujoco.MjModel, cfg) -> dict[str, LinkRef]:
    """Resolve every `cfg.link_map` key (in link_map order)."""
    return resolve_links(model, list(cfg.link_map))


@dataclass(frozen=True)
class LinkIndex:
    """Vectorised form of resolved links: positions of all of them from one MjData in link order."""

    names: tuple[str, ...]
    is_site: np.ndarray  # (L,) bool
    ids: np.ndarray  # (L,) int, body id or site id

    @classmethod
    def from_refs(cls, refs: dict[str, LinkRef]) -> LinkIndex:
        values = list(refs.values())
        return cls(
            names=tuple(refs),
            is_site=np.array([r.kind == "site" for r in values], dtype=bool),
            ids=np.array([r.id for r in values], dtype=np.int64),
        )

    def positions(self, data: mujoco.MjData) -> np.ndarray:
        """(L, 3) world positions (after mj_kinematics / mj_forward)."""
        out = np.empty((len(self.names), 3))
        out[~self.is_site] = data.xpos[self.ids[~self.is_site]]
        out[self.is_site] = data.site_xpos[self.ids[self.is_site]]
        return out
