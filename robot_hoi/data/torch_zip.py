"""Read one tensor from a `torch.save()` zip archive without unpickling anything.

The archive holds `<stem>/data.pkl` (a pickle that rebuilds the tensor) and `<stem>/data/<key>` (its raw
storage bytes). We walk the pickle's opcodes with `pickletools.genops` on a tiny symbolic stack that only
records values: no class is imported, no callable is run. The recognised structure is

    torch._utils._rebuild_tensor_v2(persistent_id(('storage', torch.<Type>Storage, key, location, numel)),
                                    storage_offset, shape, stride, requires_grad, OrderedDict())

and anything else is rejected as not a plain single-tensor file.
"""

from __future__ import annotations

import pickletools
import zipfile
from pathlib import Path

import numpy as np

from robot_hoi.errors import DataError

_STORAGE_DTYPES = {
    "FloatStorage": "<f4",
    "DoubleStorage": "<f8",
    "HalfStorage": "<f2",
    "IntStorage": "<i4",
    "LongStorage": "<i8",
}
_MARK = object()
_PUSH_ARG = {
    "BININT", "BININT1", "BININT2", "INT", "LONG", "LONG1", "LONG4", "BINFLOAT", "FLOAT",
    "BINUNICODE", "SHORT_BINUNICODE", "BINUNICODE8", "UNICODE", "BINSTRING", "SHORT_BINSTRING", "STRING",
}  # fmt: skip
_CONSTANTS = {"NEWTRUE": True, "NEWFALSE": False, "NONE": None}
# A checkpoint or any saved dict/list uses one of these; a lone tensor never does.
_CONTAINER_OPCODES = {"EMPTY_DICT", "DICT", "EMPTY_LIST", "LIST", "SETITEM", "SETITEMS", "APPENDS", "APPEND"}


class _Global(tuple):
    """('module', 'name') of a GLOBAL opcode, never resolved."""


def _symbolic_unpickle(data: bytes, path: Path):
    """Evaluate a pickle's structure symbolically (values, tuples, globals as names, calls as records)."""
    stack: list = []
    memo: dict = {}
    try:
        for op, arg, _pos in pickletools.genops(data):
            name = op.name
            if name in ("PROTO", "FRAME"):
                continue
            if name in _PUSH_ARG:
                stack.append(arg)
            elif name in _CONSTANTS:
                stack.append(_CONSTANTS[name])
            elif name == "GLOBAL":
                module, _, attr = arg.partition(" ")
                stack.append(_Global((module, attr)))
            elif name == "STACK_GLOBAL":
                attr, module = stack.pop(), stack.pop()
                stack.append(_Global((module, attr)))
            elif name == "MARK":
                stack.append(_MARK)
            elif name == "TUPLE":
                idx = len(stack) - 1 - stack[::-1].index(_MARK)
                items = tuple(stack[idx + 1 :])
                del stack[idx:]
                stack.append(items)
            elif name in ("TUPLE1", "TUPLE2", "TUPLE3"):
                n = int(name[-1])
                items = tuple(stack[-n:])
                del stack[-n:]
                stack.append(items)
            elif name == "EMPTY_TUPLE":
                stack.append(())
            elif name in ("BINPUT", "LONG_BINPUT", "PUT"):
                memo[arg] = stack[-1]
            elif name == "MEMOIZE":
                memo[len(memo)] = stack[-1]
            elif name in ("BINGET", "LONG_BINGET", "GET"):
                stack.append(memo[arg])
            elif name == "BINPERSID":
                stack.append(("persistent_id", stack.pop()))
            elif name == "REDUCE":
                args = stack.pop()
                func = stack.pop()
                stack.append(("call", func, args))
            elif name == "STOP":
                return stack.pop()
            elif name in _CONTAINER_OPCODES:
                raise DataError(
                    f"{path}: holds a dict or list (a training checkpoint?), not one clip tensor; a checkpoint "
                    "goes to `robot-hoi eval`, `robot-hoi play` or `robot-hoi export onnx`"
                )
            else:
                raise DataError(
                    f"{path}: data.pkl uses pickle opcode {name}, which a plain tensor file never does"
                )
    except DataError:
        raise
    except Exception as exc:  # malformed pickle: genops raises ValueError, our stack may underflow
        raise DataError(f"{path}: data.pkl is not a readable pickle ({exc})") from exc
    raise DataError(f"{path}: data.pkl has no STOP opcode (truncated)")


def _parse_tensor_record(record, path: Path) -> tuple[str, str, int, int, tuple[int, ...], tuple[int, ...]]:
    """-> (numpy dtype, storage key, numel, offset, shape, stride) from the symbolic pickle result."""
    bad = DataError(f"{path}: not a single-tensor torch file (unexpected data.pkl structure)")
    try:
        kind, func, args = record
        pid_kind, pid = args[0]
        storage_type, key, _location, numel = pid[1], pid[2], pid[3], pid[4]
        offset, shape, stride = args[1], tuple(args[2]), tuple(args[3])
    except (TypeError, ValueError, IndexError) as exc:
        raise bad from exc
    expected = (
        kind == "call"
        and func == ("torch._utils", "_rebuild_tensor_v2")
        and pid_kind == "persistent_id"
        and pid[0] == "storage"
        and isinstance(storage_type, _Global)
        and storage_type[0] == "torch"
        and all(isinstance(v, int) for v in (numel, offset, *shape, *stride))
    )
    if not expected:
        raise bad
    dtype = _STORAGE_DTYPES.get(storage_type[1])
    if dtype is None:
        raise DataError(f"{path}: tensor storage type {storage_type[1]} is not supported")
    return dtype, str(key), numel, offset, shape, stride


def read_torch_tensor(path: str | Path) -> np.ndarray:
    """The tensor saved in a torch zip file, as a read-only numpy array (C order), without unpickling."""
    path = Path(path)
    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError as exc:
        raise DataError(f"{path}: file not found") from exc
    except (zipfile.BadZipFile, OSError) as exc:
        raise DataError(f"{path}: not a torch zip archive (corrupt or truncated file: {exc})") from exc
    with archive:
        pkl_names = [n for n in archive.namelist() if n.endswith("/data.pkl") or n == "data.pkl"]
        if len(pkl_names) != 1:
            raise DataError(f"{path}: expected one data.pkl in the torch archive, found {len(pkl_names)}")
        prefix = pkl_names[0][: -len("data.pkl")]
        try:
            byteorder = archive.read(prefix + "byteorder").decode().strip()
        except KeyError:
            byteorder = "little"  # older torch wrote no byteorder record: always little-endian
        except (zipfile.BadZipFile, OSError, EOFError) as exc:
            raise DataError(f"{path}: corrupt torch archive ({exc})") from exc
        if byteorder != "little":
            raise DataError(f"{path}: tensor stored {byteorder}-endian; only little-endian is supported")
        try:
            record = _symbolic_unpickle(archive.read(pkl_names[0]), path)
            dtype, key, numel, offset, shape, stride = _parse_tensor_record(record, path)
            raw = archive.read(f"{prefix}data/{key}")
        except KeyError as exc:
            raise DataError(f"{path}: torch archive lacks the tensor storage ({exc})") from exc
        except (zipfile.BadZipFile, OSError, EOFError) as exc:  # CRC errors, truncated members
            raise DataError(f"{path}: corrupt torch archive ({exc})") from exc
    itemsize = np.dtype(dtype).itemsize
    if len(raw) != numel * itemsize:
        raise DataError(f"{path}: tensor storage has {len(raw)} bytes, data.pkl says {numel} x {itemsize}")
    count = int(np.prod(shape)) if shape else 1
    expected_stride = tuple(int(np.prod(shape[i + 1 :])) for i in range(len(shape)))
    if count and stride != expected_stride:
        raise DataError(f"{path}: tensor is not contiguous (stride {stride} for shape {shape})")
    if offset < 0 or offset + count > numel:
        raise DataError(f"{path}: tensor of shape {shape} at offset {offset} exceeds its storage of {numel}")
    return np.frombuffer(raw, dtype=dtype, count=count, offset=offset * itemsize).reshape(shape)
