"""pedscan's exports read by other people's readers: the ROS 2 bag decoded by the `mcap` and
`mcap-ros2-support` packages, and the SemanticKITTI files read with numpy the way the
standard loaders (semantic-kitti-api's `laserscan.py`) read them; both against the HDF5 of
the same run."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import SENSOR_TOML, generate

DATATYPES = {2: "u1", 4: "<u2", 7: "<f4"}


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("exports")
    (tmp / "sensor.toml").write_text(SENSOR_TOML)
    return generate(tmp / "out", "--sensor", str(tmp / "sensor.toml"), "--frames", "3", "--humans", "3..3",
                    "--seed", "5", "--formats", "h5,semantickitti,mcap")


def test_the_ros2_bag_decodes_to_the_hdf5(exported: Path) -> None:
    bag = exported / "seq_000000_bag"
    assert (bag / "metadata.yaml").read_text().startswith("rosbag2_bagfile_information:")
    h5 = h5py.File(exported / "seq_000000.h5", "r")
    seen = {"/pedscan/points": 0, "/tf": 0}
    with open(bag / "seq_000000.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, msg in reader.iter_decoded_messages():
            t = message.sequence
            seen[channel.topic] += 1
            if channel.topic == "/tf":
                tf = msg.transforms[0]
                assert (tf.header.frame_id, tf.child_frame_id) == ("world", "pedscan_sensor")
                pose = h5["sensor/world_from_sensor"][t]
                got = [tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z]
                np.testing.assert_allclose(got, pose[:3, 3], atol=1e-12)
                continue
            assert schema.name == "sensor_msgs/msg/PointCloud2"
            h, w = h5["range"].shape[1:]
            assert (msg.height, msg.width, msg.point_step) == (h, w, 40)
            dtype = np.dtype({"names": [fl.name for fl in msg.fields],
                              "formats": [DATATYPES[fl.datatype] for fl in msg.fields],
                              "offsets": [fl.offset for fl in msg.fields], "itemsize": msg.point_step})
            pts = np.frombuffer(bytes(msg.data), dtype=dtype).reshape(h, w)
            rng = h5["range"][t]
            hole = rng <= 0
            assert hole.any() and not msg.is_dense, "the 20 m limit leaves holes"
            xyz = np.stack([pts["x"], pts["y"], pts["z"]], -1)
            assert np.isnan(xyz[hole]).all()
            np.testing.assert_allclose(xyz[~hole], h5["xyz"][t][~hole], atol=1e-5)
            np.testing.assert_array_equal(pts["instance"], h5["instance"][t])
            np.testing.assert_array_equal(pts["label"], h5["label"][t])
            np.testing.assert_array_equal(pts["ring"][:, 0], np.arange(h)[::-1])
            vel = np.stack([pts["vx"], pts["vy"], pts["vz"]], -1)
            np.testing.assert_array_equal(vel[~hole], h5["velocity"][t][~hole])
    assert seen == {"/pedscan/points": 3, "/tf": 3}


def test_semantickitti_files_read_like_the_standard_loaders(exported: Path) -> None:
    h5 = h5py.File(exported / "seq_000000.h5", "r")
    seq = exported / "semantickitti" / "sequences" / "00"
    poses = np.loadtxt(seq / "poses.txt").reshape(-1, 3, 4)
    for t in range(3):
        # semantic-kitti-api laserscan.py: float32 reshape(-1, 4); labels uint32, & 0xFFFF, >> 16.
        scan = np.fromfile(seq / "velodyne" / f"{t:06d}.bin", dtype=np.float32).reshape(-1, 4)
        label = np.fromfile(seq / "labels" / f"{t:06d}.label", dtype=np.uint32)
        returned = h5["range"][t].reshape(-1) > 0
        assert scan.shape[0] == label.shape[0] == returned.sum()
        np.testing.assert_allclose(scan[:, :3], h5["xyz"][t].reshape(-1, 3)[returned], atol=1e-5)
        inst = h5["instance"][t].reshape(-1)[returned]
        np.testing.assert_array_equal(label >> 16, inst)
        sem = label & 0xFFFF
        assert set(np.unique(sem[inst == 0])) == {50}
        assert set(np.unique(sem[inst > 0])) <= {30, 254}
        np.testing.assert_allclose(poses[t], h5["sensor/world_from_sensor"][t][:3], atol=1e-12)
