import os
import pickle
import zipfile

import numpy as np
import pytest
import torch

from robot_hoi.data.torch_zip import read_torch_tensor
from robot_hoi.errors import DataError


def test_reads_float32_tensor_exactly(tmp_path):
    values = np.random.default_rng(0).normal(size=(7, 591)).astype(np.float32)
    torch.save(torch.from_numpy(values), tmp_path / "clip.pt")
    out = read_torch_tensor(tmp_path / "clip.pt")
    assert out.dtype == np.float32 and out.shape == (7, 591)
    np.testing.assert_array_equal(out, values)


def test_reads_a_view_with_storage_offset(tmp_path):
    base = torch.arange(24, dtype=torch.float64).reshape(6, 4)
    torch.save(base[2:], tmp_path / "view.pt")  # torch keeps the whole storage and an offset of 8
    np.testing.assert_array_equal(read_torch_tensor(tmp_path / "view.pt"), base[2:].numpy())


def test_rejects_non_tensor_pickles_without_running_them(tmp_path):
    marker = tmp_path / "pwned"

    class Exploit:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    path = tmp_path / "evil.pt"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("evil/data.pkl", pickle.dumps(Exploit(), protocol=2))
        z.writestr("evil/byteorder", "little")
    with pytest.raises(DataError, match="evil.pt"):
        read_torch_tensor(path)
    assert not marker.exists()


def test_rejects_a_saved_dict(tmp_path):
    torch.save({"a": torch.zeros(3)}, tmp_path / "dict.pt")
    with pytest.raises(DataError, match="dict.pt"):
        read_torch_tensor(tmp_path / "dict.pt")


def test_truncated_archive_is_a_clear_error(tmp_path):
    torch.save(torch.zeros(50, 591), tmp_path / "full.pt")
    data = (tmp_path / "full.pt").read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"cut\.pt.*(corrupt|truncated)"):
        read_torch_tensor(tmp_path / "cut.pt")


def test_storage_size_must_match_the_pickle(tmp_path):
    torch.save(torch.zeros(4, 591), tmp_path / "ok.pt")
    src = zipfile.ZipFile(tmp_path / "ok.pt")
    with zipfile.ZipFile(tmp_path / "short.pt", "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            dst.writestr(name, data[:-4] if name.endswith("data/0") else data)
    with pytest.raises(DataError, match="storage has"):
        read_torch_tensor(tmp_path / "short.pt")
