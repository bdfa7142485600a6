"""Two network namespaces joined by one link with a set delay, jitter and loss, for running
plant and controllers as on two machines of a lossy network (needs root).

:class:`Link` uses the kernel's netem qdisc on a veth pair, or where the kernel has no netem a
user-space emulation of it (:data:`LINK_EMULATOR`) between two TAP devices. It makes, and
removes in :meth:`Link.close`, only namespaces and devices of its own.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

#: A user-space netem for kernels without the netem qdisc: it attaches to one TAP device in each
#: namespace and copies Ethernet frames between them, dropping each with probability ``loss``
#: and delivering the rest after ``delay +- jitter`` (uniform, so frames may be reordered, as
#: with netem's jitter). On SIGTERM it prints its counts as JSON.
LINK_EMULATOR = r"""
import ctypes, fcntl, heapq, json, os, random, select, signal, struct, sys, time
ns_a, dev_a, ns_b, dev_b = sys.argv[1:5]
delay, jitter, loss = float(sys.argv[5]) / 1e3, float(sys.argv[6]) / 1e3, float(sys.argv[7])
rng = random.Random(int(sys.argv[8]))
libc = ctypes.CDLL(None, use_errno=True)

def attach(ns, dev):
    fd = os.open(f"/var/run/netns/{ns}", os.O_RDONLY)
    if libc.setns(fd, 0x40000000) != 0:  # CLONE_NEWNET
        raise OSError(ctypes.get_errno(), f"setns({ns})")
    os.close(fd)
    tap = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(tap, 0x400454CA, struct.pack("16sH", dev.encode(), 0x0002 | 0x1000))  # TAP, NO_PI
    return tap

a, b = attach(ns_a, dev_a), attach(ns_b, dev_b)
peer = {a: b, b: a}
queue, seq, stats, stop = [], 0, {"frames": 0, "dropped": 0, "delivered": 0}, []
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
signal.signal(signal.SIGINT, lambda *_: stop.append(1))
print("ready", flush=True)
while not stop:
    timeout = max(0.0, queue[0][0] - time.monotonic()) if queue else 0.2
    try:
        ready = select.select([a, b], [], [], timeout)[0]
    except InterruptedError:
        continue
    now = time.monotonic()
    for fd in ready:
        while True:
            try:
                frame = os.read(fd, 65536)
            except (BlockingIOError, InterruptedError):
                break
            stats["frames"] += 1
            if rng.random() < loss:
                stats["dropped"] += 1
                continue
            due = now + max(0.0, delay + rng.uniform(-jitter, jitter))
            heapq.heappush(queue, (due, seq, peer[fd], frame))
            seq += 1
    now = time.monotonic()
    while queue and queue[0][0] <= now:
        _, _, fd, frame = heapq.heappop(queue)
        try:
            os.write(fd, frame)
            stats["delivered"] += 1
        except OSError:
            pass
print(json.dumps(stats), flush=True)
"""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run an ``ip`` or ``tc`` command; with ``check``, a failure raises with its stderr."""
    proc = subprocess.run(args, capture_output=True, text=True, timeout=20)
    if check and proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)}: {proc.stderr.strip()}")
    return proc


class Link:
    """Two network namespaces made by this test, joined by one link; everything in them is ours.

    ``kind`` is ``"netem"`` (a veth pair with the kernel's netem qdisc on both ends) or, where
    the kernel has no netem (``tc`` says "Specified qdisc kind is unknown"), ``"tap"``: a TAP
    device in each namespace joined by :data:`LINK_EMULATOR`. Addresses 10.200.0.1/30 and
    10.200.0.2/30 exist only inside the two namespaces.
    """

    ADDRESSES = ("10.200.0.1", "10.200.0.2")

    def __init__(self, tmp_path: Path, extra_env: dict[str, str] | None = None) -> None:
        self.extra_env = dict(extra_env or {})
        tag = f"{os.getpid() % 100000:05d}{random.randrange(1000):03d}"
        self.ns = (f"apcA{tag}", f"apcB{tag}")
        self.dev = (f"apcA{tag}", f"apcB{tag}")  # 12 characters (limit 15)
        self.dir = tmp_path
        self.kind = ""
        self.emulator: subprocess.Popen | None = None
        self.stats: list[dict] = []
        self._made: list[str] = []

    def make(self) -> None:
        for ns in self.ns:
            try:
                proc = _ip("ip", "netns", "add", ns, check=False)
            except FileNotFoundError:
                pytest.skip("network namespaces refused: no 'ip' command (iproute2)")
            if proc.returncode != 0:
                pytest.skip(f"network namespaces refused: {proc.stderr.strip()}")
            self._made.append(ns)
        (a, b), (da, db) = self.ns, self.dev
        _ip("ip", "-n", a, "link", "add", da, "type", "veth", "peer", "name", db, "netns", b)
        try:
            probe = _ip(
                "tc", "-n", a, "qdisc", "add", "dev", da, "root", "netem", "delay", "1ms",
                check=False,
            )  # fmt: skip
            netem_error = (probe.stderr.strip() or "tc failed") if probe.returncode else ""
        except FileNotFoundError:
            netem_error = "no 'tc' command"
        if not netem_error:
            self.kind = "netem"
            _ip("tc", "-n", a, "qdisc", "del", "dev", da, "root")
        else:
            self.kind = "tap"
            _ip("ip", "-n", a, "link", "del", da)
            for ns, dev in ((a, da), (b, db)):
                tap = _ip("ip", "-n", ns, "tuntap", "add", "dev", dev, "mode", "tap", check=False)
                if tap.returncode != 0:
                    pytest.skip(
                        f"no link emulation: netem qdisc unavailable ({netem_error}) and TAP "
                        f"devices refused ({tap.stderr.strip()})"
                    )
        for ns, dev, addr in zip(self.ns, self.dev, self.ADDRESSES, strict=True):
            _ip("ip", "-n", ns, "link", "set", "lo", "up")
            _ip("ip", "-n", ns, "addr", "add", f"{addr}/30", "dev", dev)
            _ip("ip", "-n", ns, "link", "set", "dev", dev, "multicast", "on", "up")
            _ip("ip", "-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)

    def impair(self, delay_ms: float, jitter_ms: float, loss: float) -> None:
        """Set the link's delay (each way), jitter and loss probability (each way)."""
        if self.kind == "netem":
            for ns, dev in zip(self.ns, self.dev, strict=True):
                if delay_ms or loss:
                    _ip(
                        "tc", "-n", ns, "qdisc", "replace", "dev", dev, "root", "netem",
                        "delay", f"{delay_ms}ms", f"{jitter_ms}ms", "loss", f"{100 * loss}%",
                    )  # fmt: skip
                else:
                    _ip("tc", "-n", ns, "qdisc", "del", "dev", dev, "root", check=False)
            return
        self._stop_emulator()
        self.emulator = subprocess.Popen(
            [sys.executable, "-c", LINK_EMULATOR, self.ns[0], self.dev[0], self.ns[1],
             self.dev[1], str(delay_ms), str(jitter_ms), str(loss), str(random.randrange(10**6))],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        line = self.emulator.stdout.readline()  # type: ignore[union-attr]
        assert line.strip() == "ready", self.emulator.stderr.read()  # type: ignore[union-attr]

    def _stop_emulator(self) -> None:
        if self.emulator is None:
            return
        self.emulator.terminate()
        try:
            out, _ = self.emulator.communicate(timeout=5)
            self.stats.append(yaml.safe_load(out.strip().splitlines()[-1]))
        except (subprocess.TimeoutExpired, IndexError, yaml.YAMLError):
            self.emulator.kill()
            self.emulator.wait()
        self.emulator = None

    def env(self, side: int) -> dict[str, str]:
        """Environment of a node in namespace ``side``: DDS over UDP on the subnet, with the
        other side as a static peer (no shared memory: it would bypass the link)."""
        env = dict(os.environ)
        env.update(
            ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
            ROS_STATIC_PEERS=self.ADDRESSES[1 - side],
            FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
        )
        env.update(self.extra_env)
        return env

    def prefix(self, side: int) -> tuple[str, ...]:
        return ("ip", "netns", "exec", self.ns[side])

    def close(self) -> None:
        self._stop_emulator()
        for ns in self._made:
            _ip("ip", "netns", "del", ns, check=False)
        self._made.clear()
