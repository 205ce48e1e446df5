"""`hsi record` on the simulated world: the MCAP file reads back in the independent mcap readers."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hsi_nodes.bag import bag_paths, read_bag
from hsi_nodes.pointcloud2 import msg_to_cloud


def test_hsi_record_world_is_read_by_mcap_readers(tmp_path: Path, repo_root: Path) -> None:
    out = tmp_path / "world.mcap"
    cmd = [
        sys.executable, "-m", "hsi_nodes.cli", "record", "--out", str(out),
        "--launch", str(repo_root / "launch" / "sim_world.launch.yaml"),
        "--duration", "0.2", "--sim-time", "cloud_period:=0",
    ]  # fmt: skip
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=240, check=False)
    assert run.returncode == 0, run.stderr[-2000:]

    ours = list(read_bag(out))
    topics = {m.topic for m in ours}
    assert {"/scene/points", "/tf", "/scene/joint_states", "/robot/joint_states"} <= topics

    _, mcap_file = bag_paths(out)
    with mcap_file.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()], validate_crcs=True)
        theirs = list(reader.iter_decoded_messages())
    assert len(theirs) == len(ours)
    for mine, (schema, channel, message, decoded) in zip(ours, theirs, strict=True):
        assert channel.topic == mine.topic
        assert schema.name == mine.typename
        assert message.log_time == mine.t_ns
        if mine.topic.endswith("joint_states"):
            assert list(decoded.name) == list(mine.msg.name)
            assert np.allclose(decoded.position, mine.msg.position)
        if mine.topic == "/tf":
            got = [(t.child_frame_id, t.transform.translation.z) for t in decoded.transforms]
            assert got == [(t.child_frame_id, t.transform.translation.z) for t in mine.msg.transforms]

    # The cloud is identical, byte for byte, and still decodes to labelled points.
    cloud_ours = next(m.msg for m in ours if m.topic == "/scene/points")
    cloud_theirs = next(d for _, c, _, d in theirs if c.topic == "/scene/points")
    assert bytes(cloud_theirs.data) == bytes(np.asarray(cloud_ours.data, dtype=np.uint8))
    assert (cloud_theirs.width, cloud_theirs.point_step) == (cloud_ours.width, cloud_ours.point_step)
    points, labels, dropped = msg_to_cloud(cloud_ours)
    assert points.shape[0] > 10_000 and labels is not None and dropped == 0
    assert len(np.unique(labels)) >= 10
