"""rosbag2-compatible MCAP, crash safety: a truncated bag yields every message of its complete
chunks and ``recover()`` / ``bag_recover`` make it complete again; a chunk is in the stream as
soon as it is complete; a writer killed with SIGKILL loses at most its open chunk.
"""

from __future__ import annotations

import io
import select
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from bag_helpers import T_NS, _cdr, _joint_state, _write
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState

import apc_msgs_py as wire
from apc_recording import bag
from apc_recording.bag import BagTruncatedWarning, BagWriter
from apc_recording.bag.recovery import main as bag_recover


def _complete_chunks_end_times(data: bytes) -> list[tuple[int, int]]:
    """(end offset, last log time) of each chunk of a finished bag, from its chunk index."""
    summary = make_reader(io.BytesIO(data)).get_summary()
    return [
        (c.chunk_start_offset + c.chunk_length, c.message_end_time) for c in summary.chunk_indexes
    ]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_truncated_file_yields_every_message_of_the_complete_chunks(tmp_path, compression):
    buffer = io.BytesIO()
    times = [k * T_NS for k in range(300)]
    with BagWriter(buffer, chunk_size=2000, compression=compression) as writer:
        writer.add_topic(wire.JOINT_STATES, JointState, wire.CONTROL_QOS)
        for k, t in enumerate(times):
            writer.write(wire.JOINT_STATES, _cdr(_joint_state(6, k)), t)
    full = buffer.getvalue()
    chunks = _complete_chunks_end_times(full)
    assert len(chunks) > 20
    data_end = chunks[-1][0]
    rng = np.random.default_rng(0)
    cuts = sorted({*(end for end, _ in chunks), *(end - 1 for end, _ in chunks[:5])}) + [
        int(c) for c in rng.integers(8, data_end, size=25)
    ]
    for cut in cuts:
        done = [last for end, last in chunks if end <= cut]
        expected = [t for t in times if done and t <= done[-1]]
        with pytest.warns(BagTruncatedWarning, match="complete chunks"):
            read = list(bag.read_messages(io.BytesIO(full[:cut])))
        assert [m.log_time_ns for m in read] == expected, cut
        assert all(m.decode() == _joint_state(6, m.log_time_ns // T_NS) for m in read)
        info = bag.bag_info(io.BytesIO(full[:cut]))
        assert not info["complete"] and info["message_count"] == len(expected)
    # the same from a file on disk, and recover() makes it complete again
    cut = chunks[len(chunks) // 2][0] + 100
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(full[:cut])
    fixed = tmp_path / "fixed.mcap"
    count = bag.recover(broken, fixed)
    expected = [t for t in times if t <= chunks[len(chunks) // 2][1]]
    assert count == len(expected)
    info = bag.bag_info(fixed)
    assert info["complete"] and info["message_count"] == count
    assert info["topics"][wire.JOINT_STATES]["offered_qos_profiles"] == bag.qos_profiles_to_yaml(
        [wire.CONTROL_QOS]
    )
    assert [m.log_time_ns for m in bag.read_messages(fixed)] == expected
    with AnyReader([fixed]) as reader:
        assert sum(1 for _ in reader.messages()) == count


def test_bag_recover_command(tmp_path, capsys):
    """``bag_recover BROKEN FIXED``: one line on stdout; errors name the problem, exit 1, and
    leave no file behind."""
    buffer = io.BytesIO()
    with BagWriter(buffer, chunk_size=2000) as writer:
        writer.add_topic(wire.JOINT_STATES, JointState, wire.CONTROL_QOS)
        for k in range(100):
            writer.write(wire.JOINT_STATES, _cdr(_joint_state(6, k)), k * T_NS)
    full = buffer.getvalue()
    end, last = _complete_chunks_end_times(full)[3]
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(full[: end + 50])
    fixed = tmp_path / "fixed.mcap"
    assert bag_recover([str(broken), str(fixed)]) == 0
    count = last // T_NS + 1
    line = f"{broken} ends before its footer: {count} messages on 1 topics written to {fixed}"
    assert capsys.readouterr().out.strip() == line
    assert bag.bag_info(fixed)["complete"] and bag.bag_info(fixed)["message_count"] == count
    with AnyReader([fixed]) as reader:
        assert sum(1 for _ in reader.messages()) == count

    assert bag_recover([str(broken), str(fixed)]) == 1  # never replaced unless asked
    assert "exists (--force replaces it)" in capsys.readouterr().err
    assert bag_recover([str(fixed), str(fixed), "--force"]) == 1
    assert "the destination is the source" in capsys.readouterr().err
    complete = tmp_path / "complete.mcap"
    complete.write_bytes(full)
    assert bag_recover([str(complete), str(fixed), "--force", "--compression", "lz4"]) == 0
    assert capsys.readouterr().out.startswith(f"{complete} was complete: 100 messages")
    assert bag.bag_info(fixed)["message_count"] == 100

    not_a_bag = tmp_path / "notes.txt"
    not_a_bag.write_text("hello world, this is not a bag at all")
    out = tmp_path / "out.mcap"
    assert bag_recover([str(not_a_bag), str(out)]) == 1
    assert "not an MCAP file (bad magic)" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "broken.mcap",
        "complete.mcap",
        "fixed.mcap",
        "notes.txt",
    ]


def test_a_chunk_is_in_the_stream_as_soon_as_it_is_complete():
    """No finish(): what is in the stream already is every complete chunk (nothing buffered)."""
    buffer = io.BytesIO()
    writer = BagWriter(buffer, chunk_size=1500, max_chunk_interval_ns=None)
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(6, k), k * T_NS)
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(io.BytesIO(buffer.getvalue())))
    per_chunk = 1500 // len(_cdr(_joint_state(6))) + 1
    assert 100 - per_chunk <= len(read) < 100
    # max_chunk_interval_ns bounds the loss in (log) time, too
    buffer = io.BytesIO()
    writer = BagWriter(buffer, max_chunk_interval_ns=5 * T_NS)
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(6, k), k * T_NS)
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(io.BytesIO(buffer.getvalue())))
    assert 100 - 6 <= len(read) < 100
    writer.flush()  # an explicit flush closes the open chunk
    with pytest.warns(BagTruncatedWarning):  # still no footer: finish() writes it
        assert len(list(bag.read_messages(io.BytesIO(buffer.getvalue())))) == 100


_CHILD = textwrap.dedent(
    """
    import sys, time
    from rclpy.serialization import serialize_message
    import apc_msgs_py as wire
    from apc_recording import bag
    import numpy as np
    path, n = sys.argv[1], int(sys.argv[2])
    writer = bag.BagWriter(path, chunk_size=2048)
    writer.add_topic(wire.JOINT_STATES, "sensor_msgs/msg/JointState", wire.CONTROL_QOS)
    for k in range(n):
        t = k * 10_000_000
        msg = wire.arrays_to_joint_state(t, ["a", "b", "c"], np.full(3, k), np.zeros(3))
        writer.write(wire.JOINT_STATES, bytes(serialize_message(msg)), t)
    print("written", flush=True)
    time.sleep(60)
    """
)


def test_sigkill_loses_at_most_the_open_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    n = 1000
    errors = tmp_path / "child.err"
    with open(errors, "w") as stderr:
        child = subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(path), str(n)],
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
        )
    try:
        ready, _, _ = select.select([child.stdout], [], [], 30.0)
        line = child.stdout.readline() if ready else ""
        assert line.strip() == "written", f"child did not finish writing: {errors.read_text()}"
    finally:
        child.send_signal(signal.SIGKILL)  # no finish(): the file has no summary and no footer
        child.wait(timeout=10)
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(path))
    size = len(serialize_message(wire.arrays_to_joint_state(0, ["a", "b", "c"], np.zeros(3))))
    per_chunk = 2048 // size + 1
    assert n - per_chunk <= len(read) < n
    assert [m.log_time_ns for m in read] == [k * T_NS for k in range(len(read))]
    assert [m.decode().position[0] for m in read] == [float(k) for k in range(len(read))]
