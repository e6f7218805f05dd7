"""The reader against h5py directly: shapes, values, laziness and errors."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import ELEVATION_DEG
from pedscan_data import BEAM_FIELDS, PedscanError, Sequence, open_sequences


def test_folder_gives_every_sequence_sorted(sample: Path) -> None:
    seqs = open_sequences(sample)
    assert [s.path.name for s in seqs] == ["seq_000000.h5", "seq_000001.h5"]
    assert [s.index for s in seqs] == [0, 1]
    assert [s.path for s in open_sequences(sample / "seq_000001.h5")] == [sample / "seq_000001.h5"]


def test_attributes_beam_table_poses_and_people_match_the_file(sample: Path) -> None:
    path = sample / "seq_000001.h5"
    seq = Sequence(path)
    with h5py.File(path, "r") as f:
        assert (seq.frames, seq.rows, seq.columns) == (4, 16, 512) == f["range"].shape
        assert seq.seed == 3 and seq.index == 1 and seq.sensor == "test16"
        assert seq.version == f.attrs["pedscan_version"]
        assert "seed = 3" in seq.config
        assert seq.fields == BEAM_FIELDS
        np.testing.assert_array_equal(seq.elevation_deg, np.array(ELEVATION_DEG, np.float32))
        np.testing.assert_array_equal(seq.azimuth_deg, f["sensor/azimuth_deg"][()])
        assert seq.azimuth_deg.shape == (512,)
        np.testing.assert_array_equal(seq.time_s, f["sensor/time_s"][()])
        np.testing.assert_array_equal(seq.world_from_sensor, f["sensor/world_from_sensor"][()])
        assert seq.world_from_sensor.shape == (4, 4, 4)
        n = f["humans/height_m"].shape[0]
        assert 2 <= n <= 4 and len(seq.humans.model) == n
        assert all(isinstance(m, str) and m for m in seq.humans.model)
        for key in ("height_m", "weight_kg", "position_m", "heading_rad", "gait_phase", "velocity_mps"):
            np.testing.assert_array_equal(getattr(seq.humans, key), f["humans/" + key][()])
        assert seq.humans.position_m.shape == (4, n, 3)
        assert seq.humans.gait_phase.shape == (4, n)


def test_frames_match_the_file(sample: Path) -> None:
    path = sample / "seq_000000.h5"
    seq = Sequence(path)
    with h5py.File(path, "r") as f:
        for t, frame in enumerate(seq.iter_frames(BEAM_FIELDS)):
            assert (frame.sequence, frame.index, frame.time_s) == (0, t, f["sensor/time_s"][t])
            for key in BEAM_FIELDS:
                got = getattr(frame, key.replace("/", "_"))
                assert got.dtype == f[key].dtype
                assert got.shape == (16, 512) + ((3,) if key in ("xyz", "velocity") else ())
                np.testing.assert_array_equal(got, f[key][t])
        np.testing.assert_array_equal(seq.read("range", slice(1, 3)), f["range"][1:3])
        np.testing.assert_array_equal(seq.frame(-1).label, f["label"][3])
        # The first frame counted from the end; each frame carries its own pose.
        first = seq.frame(-4)
        assert first.index == 0 and first.time_s == f["sensor/time_s"][0]
        for t in range(4):
            np.testing.assert_array_equal(seq.frame(t).world_from_sensor, f["sensor/world_from_sensor"][t])
        assert not np.array_equal(f["sensor/world_from_sensor"][0], f["sensor/world_from_sensor"][3])


def test_frame_reads_only_what_is_asked(sample: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reads: list[tuple[str, object]] = []
    original = h5py.Dataset.__getitem__

    def recording(self: h5py.Dataset, key: object) -> object:
        reads.append((self.name, key))
        return original(self, key)

    monkeypatch.setattr(h5py.Dataset, "__getitem__", recording)
    seq = Sequence(sample / "seq_000000.h5")
    per_beam = {"/" + k for k in BEAM_FIELDS}
    assert not [r for r in reads if r[0] in per_beam], "opening read a per-beam dataset"
    reads.clear()
    frame = seq.frame(2)
    assert sorted(reads) == [("/instance", 2), ("/label", 2), ("/range", 2)]
    assert frame.xyz is None and frame.velocity is None and frame.background_range is None
    reads.clear()
    seq.read("velocity", slice(1, 3))
    assert reads == [("/velocity", slice(1, 3))]


def test_missing_dataset_names_the_file(sample_minimal: Path) -> None:
    path = sample_minimal / "seq_000000.h5"
    seq = Sequence(path)
    assert seq.fields == ("range", "label", "instance", "intensity")  # the sensor model adds intensity
    assert not seq.has("velocity")
    with pytest.raises(PedscanError, match=r"seq_000000\.h5: no dataset /velocity \(not in the --outputs it was written with\)$"):
        seq.read("velocity", 0)
    with pytest.raises(PedscanError, match=r"seq_000000\.h5: no dataset /humans/nothing$"):
        seq.dataset("humans/nothing")
    with pytest.raises(PedscanError, match=r"seq_000000\.h5: no dataset /xyz"):
        seq.frame(0, ("range", "xyz"))


def test_files_that_are_not_sequences_are_named(tmp_path: Path) -> None:
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["range"] = np.zeros((1, 2, 3), np.float32)
    with pytest.raises(PedscanError, match=r"other\.h5: not a pedscan sequence"):
        Sequence(other)
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(PedscanError, match=r"notes\.h5: not an HDF5 file"):
        Sequence(text)
    with pytest.raises(FileNotFoundError, match=r"absent\.h5"):
        Sequence(tmp_path / "absent.h5")
    with pytest.raises(PedscanError, match="no seq_"):
        open_sequences(tmp_path)


def test_frame_out_of_range_names_the_file(sample: Path) -> None:
    with pytest.raises(IndexError, match=r"seq_000000\.h5: frame 4 of 4"):
        Sequence(sample / "seq_000000.h5").frame(4)
    with pytest.raises(IndexError, match=r"seq_000000\.h5: frame -5 of 4"):
        Sequence(sample / "seq_000000.h5").frame(-5)
    seq = Sequence(sample / "seq_000000.h5")
    np.testing.assert_array_equal(seq.read("range", -4), seq.read("range", 0))
    for t in (4, -5):
        with pytest.raises(IndexError, match=rf"seq_000000\.h5: frame {t} of 4"):
            seq.read("range", t)


def test_close_closes_the_file_once_and_a_later_read_reopens_it(sample: Path) -> None:
    seq = Sequence(sample / "seq_000000.h5")
    first = seq.dataset("range")
    assert first.id.valid
    seq.close()
    assert not first.id.valid, "the file is closed"
    seq.close()  # closing a closed sequence is harmless
    again = seq.dataset("range")
    assert again.id.valid
    with seq:
        pass
    assert not again.id.valid, "leaving a with block closes it"


def test_string_attributes_missing_or_stored_as_bytes(sample: Path, tmp_path: Path) -> None:
    path = tmp_path / "seq.h5"
    path.write_bytes((sample / "seq_000000.h5").read_bytes())
    with h5py.File(path, "r+") as f:
        del f.attrs["config"]
        f.attrs["sensor"] = np.bytes_(b"HDL-32E, as bytes")
    seq = Sequence(path)
    assert seq.config == ""
    assert seq.sensor == "HDL-32E, as bytes"


def test_provenance_is_read_as_its_key_value_lines(sample: Path, tmp_path: Path) -> None:
    # pedscan's own: the conftest runs the ray caster in the bundled hall.
    prov = Sequence(sample / "seq_000000.h5").provenance
    assert prov["backend"] == "raycast" and prov["background"].startswith("environment ")
    assert -1.0 < float(prov["floor_z_m"]) < 1.0
    # A value may hold '=' (split at the first); a line without one is not a key.
    path = tmp_path / "seq.h5"
    path.write_bytes((sample / "seq_000000.h5").read_bytes())
    with h5py.File(path, "r+") as f:
        f.attrs["provenance"] = "backend=raster\nrecording=ouster.pcap window=3 rate=10\nno key here\nfloor_z_m=-1.5000\n"
    assert Sequence(path).provenance == {"backend": "raster", "recording": "ouster.pcap window=3 rate=10", "floor_z_m": "-1.5000"}
