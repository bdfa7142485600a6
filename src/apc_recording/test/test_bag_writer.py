"""rosbag2-compatible MCAP, the writer's and the reader's behaviour: small chunks, lz4 and an
idempotent finish, the writer's errors, the context manager, the reader's filters and order, a
non-seekable stream, and a file that is not an MCAP.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from bag_helpers import T_NS, _cdr, _joint_state, _write, _write_run
from mcap.reader import make_reader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

import apc_msgs_py as wire
from apc_recording import bag
from apc_recording.bag import BagError, BagWriter


def test_small_chunks_lz4_and_idempotent_finish():
    buffer = io.BytesIO()
    writer = BagWriter(buffer, chunk_size=512, compression="lz4")
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(7, k), k * T_NS)
    assert writer.topics == {wire.JOINT_STATES: "sensor_msgs/msg/JointState"}
    assert writer.message_count == 100
    writer.finish()
    writer.finish()
    assert writer.finished
    buffer.seek(0)
    summary = make_reader(buffer).get_summary()
    assert summary.statistics.chunk_count > 10
    assert {c.compression for c in summary.chunk_indexes} == {"lz4"}
    read = list(bag.read_messages(buffer))
    assert [m.decode() for m in read] == [_joint_state(7, k) for k in range(100)]
    with pytest.raises(BagError, match="finished"):
        writer.write(wire.JOINT_STATES, read[0].data, 0)


def test_writer_errors(tmp_path):
    with pytest.raises(BagError, match="compression"):
        BagWriter(io.BytesIO(), compression="gzip")
    with pytest.raises(BagError, match="chunk_size"):
        BagWriter(io.BytesIO(), chunk_size=0)
    with pytest.raises(BagError, match="cannot create bag"):
        BagWriter(tmp_path / "missing_dir" / "x.mcap")
    data = _cdr(_joint_state(3))
    with BagWriter(io.BytesIO()) as writer:
        assert writer.add_topic("js", "sensor_msgs/msg/JointState") == writer.add_topic(
            "js", JointState
        )
        with pytest.raises(BagError, match="already added with type"):
            writer.add_topic("js", Clock)
        with pytest.raises(BagError, match="was not added"):
            writer.write("other", data, 0)
        with pytest.raises(BagError, match="not CDR"):
            writer.write("js", b"\x07\x07\x00\x00abcd", 0)
        with pytest.raises(BagError, match="integer nanoseconds"):
            writer.write("js", data, 0.5)
        with pytest.raises(BagError, match="outside"):
            writer.write("js", data, -1)
        with pytest.raises(BagError, match=r"no msg/Nope\.msg"):
            writer.add_topic("nope", "sensor_msgs/msg/Nope")
        writer.write("js", data, np.int64(5))


def test_context_manager_finishes_on_exception_and_closes_only_its_file(tmp_path):
    path = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError), BagWriter(path) as writer:
        _write(writer, "js", _joint_state(3), 1)
        raise RuntimeError("boom")
    assert writer._owned.closed
    assert bag.bag_info(path)["complete"]
    assert [m.decode() for m in bag.read_messages(path)] == [_joint_state(3)]


def test_read_filters_and_orders(tmp_path):
    path = tmp_path / "f.mcap"
    times = [30, 10, 20, 10, 40]
    with BagWriter(path) as writer:
        for i, t in enumerate(times):
            _write(writer, "a" if i % 2 == 0 else "b", String(data=str(i)), t)

    def data(**kw):
        return [m.decode().data for m in bag.read_messages(path, **kw)]

    assert data(log_time_order=False) == ["0", "1", "2", "3", "4"]
    assert data() == ["1", "3", "2", "0", "4"]
    assert data(topics="a") == ["2", "0", "4"]
    assert data(topics=["b"]) == ["1", "3"]
    assert data(start_ns=20, end_ns=40) == ["2", "0"]  # end excluded
    with open(path, "rb") as stream:  # a stream is read from its start and left open
        stream.read(10)
        assert len(list(bag.read_messages(stream))) == 5
        assert not stream.closed


class _NonSeekable(io.RawIOBase):
    def __init__(self, data: bytes) -> None:
        self._inner = io.BytesIO(data)

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        chunk = self._inner.read(min(len(b), 7))  # short reads, like a pipe
        b[: len(chunk)] = chunk
        return len(chunk)


def test_non_seekable_stream_is_scanned():
    buffer = io.BytesIO()
    written = _write_run(buffer)
    stream = _NonSeekable(buffer.getvalue())
    read = list(bag.read_messages(stream, log_time_order=False))
    assert [m.data for m in read] == [w[4] for w in written]
    info = bag.bag_info(_NonSeekable(buffer.getvalue()))
    assert info["complete"] and info["message_count"] == len(written)


def test_not_an_mcap():
    with pytest.raises(BagError, match="not an MCAP"):
        list(bag.read_messages(io.BytesIO(b"hello world, this is not a bag at all")))
    with pytest.raises(BagError, match="cannot open"):
        list(bag.read_messages("/nonexistent/x.mcap"))
