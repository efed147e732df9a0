"""Content digests (memo keys) and the in-process retarget memo built on them."""

import dataclasses

import numpy as np
import pytest

from robot_hoi.utils.fingerprint import fingerprint


@dataclasses.dataclass
class _Clip:
    name: str
    pos: np.ndarray
    _cache: object = None


def test_equal_content_equal_digest_and_any_change_differs():
    a = _Clip("a", np.arange(6.0).reshape(2, 3), _cache=object())
    b = _Clip("a", np.arange(6.0).reshape(2, 3), _cache=object())
    assert fingerprint(a) == fingerprint(b)  # private caches are left out
    changed = _Clip("a", a.pos.copy())
    changed.pos[1, 2] += 1e-9
    assert fingerprint(changed) != fingerprint(a)
    assert fingerprint(_Clip("a", a.pos.reshape(3, 2))) != fingerprint(a)  # same bytes, other shape
    assert fingerprint(_Clip("a", a.pos.astype(np.float32))) != fingerprint(a)
    assert fingerprint({"x": 1, "y": [1, 2]}) == fingerprint({"y": [1, 2], "x": 1})
    assert fingerprint((1, 2)) != fingerprint([1, 2])


@pytest.mark.slow
def test_retargets_are_memoised_by_content_and_handed_out_as_copies(monkeypatch):
    from robot_hoi.data.synth import default_clip
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.retarget import pipeline
    from robot_hoi.tasks.interaction import factory

    calls = []
    real = pipeline.retarget_clip
    # counted where the factory calls it (it imports the function at its top)
    monkeypatch.setattr(factory, "retarget_clip", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(factory, "_RETARGETS", type(factory._RETARGETS)())
    embodiment, clip = load_embodiment("g1_inspire"), default_clip()
    first = factory.load_or_retarget(clip, embodiment, None)
    first.qpos[:] = 0.0  # a caller changing its copy does not change the memo
    again = factory.load_or_retarget(default_clip(), embodiment, None)
    assert len(calls) == 1 and np.abs(again.qpos).max() > 0.1
    other = default_clip()
    other.object_pos[:, 0] += 0.05  # another clip: retargeted anew
    factory.load_or_retarget(other, embodiment, None)
    assert len(calls) == 2
