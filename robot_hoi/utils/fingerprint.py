"""A content digest of nested Python values (dataclasses, dicts, sequences, numpy arrays, scalars): equal content
gives equal digests, any changed number or shape a different one. Dataclass fields named `_...` (derived caches)
are left out; an object without a content repr only makes digests differ (a memo miss, never a false hit). For
in-process memo keys, not for security."""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any

import numpy as np


def fingerprint(value: Any) -> str:
    digest = hashlib.sha256()
    _feed(digest, value)
    return digest.hexdigest()


def _feed(digest, value: Any) -> None:
    if isinstance(value, np.ndarray):
        digest.update(f"nd{value.dtype.str}{value.shape}".encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        digest.update(type(value).__qualname__.encode())
        for f in dataclasses.fields(value):
            if f.name.startswith("_"):  # private caches (a KD-tree, ...) are derived from the other fields
                continue
            digest.update(f.name.encode())
            _feed(digest, getattr(value, f.name))
    elif isinstance(value, dict):
        digest.update(b"{")
        for key in sorted(value, key=repr):
            _feed(digest, key)
            _feed(digest, value[key])
        digest.update(b"}")
    elif isinstance(value, (list, tuple)):
        digest.update(b"[" if isinstance(value, list) else b"(")
        for item in value:
            _feed(digest, item)
        digest.update(b"]")
    else:
        digest.update(f"{type(value).__name__}:{value!r};".encode())
