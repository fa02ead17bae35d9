"""The DAQ node of the CANopen cross-check, played by python-canopen (a stack nobody on this project
wrote): a canopen.LocalNode with the object dictionary of configs/canopen/ident-sim-daq.eds answers
ident's SDO and NMT, produces its heartbeat (0x1017), and on every SYNC while operational sends the
TPDOs that ident mapped, packed by python-canopen's PDO module, carrying a known signal.

The CAN bus is a pipe: one frame per line in `cansend` notation (`585#4F18100001000000`), read from
stdin and written to stdout, through a python-can bus class below. Run by
acquire/tests/canopen_python.rs.

    python_node.py EDS NODE_ID [--bus IFACE] [--silent-after N] [--emcy-at N CODE]

--bus IFACE: the bus is the SocketCAN interface IFACE (vcan0 in the test VM) through python-can's
  socketcan interface instead of the pipe; stdin still tells the node when the test is over (EOF).

--silent-after N: after N SYNCs the node stops its heartbeat and sends nothing more.
--emcy-at N CODE: at the N-th SYNC the node sends an EMCY with error code CODE (hex), register 1.
"""

import argparse
import queue
import sys
import threading

import can
import canopen


def count(ch, k):
    """The ADC count of device channel `ch` (0-based) at sample `k`: the Rust test's formula."""
    return ((k * 37 + ch * 4001) % 30000) - 15000


class PipeBus(can.BusABC):
    """python-can bus over stdin/stdout, one frame per line in cansend notation."""

    def __init__(self, closed, **kwargs):
        self._closed = closed
        self._rx = queue.Queue()
        self._lock = threading.Lock()
        self.channel_info = "stdio pipe"
        threading.Thread(target=self._reader, daemon=True).start()
        super().__init__(channel="stdio", **kwargs)

    def _reader(self):
        for line in sys.stdin:
            line = line.strip()
            if not line:
                continue
            ident, _, data = line.partition("#")
            self._rx.put(can.Message(arbitration_id=int(ident, 16), data=bytes.fromhex(data),
                                     is_extended_id=len(ident) > 3))
        # ident closed the pipe: the test is over.
        self._closed.set()

    def _recv_internal(self, timeout):
        try:
            return self._rx.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def send(self, msg, timeout=None):
        ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
        with self._lock:
            sys.stdout.write(f"{ident}#{bytes(msg.data).hex().upper()}\n")
            sys.stdout.flush()

    def shutdown(self):
        super().shutdown()


def main():
    p = argparse.ArgumentParser()
    p.add_argument("eds")
    p.add_argument("node_id", type=int)
    p.add_argument("--bus")
    p.add_argument("--silent-after", type=int)
    p.add_argument("--emcy-at", nargs=2)
    a = p.parse_args()

    network = canopen.Network()
    closed = threading.Event()
    if a.bus:
        network.bus = can.Bus(interface="socketcan", channel=a.bus)

        def watch_stdin():
            for _ in sys.stdin:
                pass
            closed.set()

        threading.Thread(target=watch_stdin, daemon=True).start()
    else:
        network.bus = PipeBus(closed)
    node = canopen.LocalNode(a.node_id, a.eds)
    network.add_node(node)
    network.connect()
    network.send_message(0x700 + a.node_id, [0])  # boot-up
    if a.bus:
        # On a real bus, frames sent before this process listens are lost: say when it does.
        print("ready", flush=True)

    syncs = 0
    sample = 0
    silent = False

    def on_nmt(can_id, data, timestamp):
        nonlocal sample
        if len(data) == 2 and data[0] == 0x01 and data[1] in (0, a.node_id):
            # NMT start: the sample counter restarts; the mapping ident wrote over SDO is read
            # back from the local object dictionary into python-canopen's PDO maps.
            sample = 0
            node.tpdo.read()

    def on_sync(can_id, data, timestamp):
        nonlocal syncs, sample, silent
        if silent or node.nmt.state != "OPERATIONAL":
            return
        syncs += 1
        if a.silent_after is not None and syncs > a.silent_after:
            silent = True
            node.nmt.stop_heartbeat()
            return
        if a.emcy_at is not None and syncs == int(a.emcy_at[0]):
            node.emcy.send(int(a.emcy_at[1], 16), register=1)
        for m in node.tpdo.map.values():
            if not m.enabled or m.trans_type is None or not 1 <= m.trans_type <= 240:
                continue
            for var in m.map:
                if var.index == 0x2100:
                    var.raw = sample & 0xFFFF
                elif var.index == 0x7100:
                    var.raw = count(var.subindex - 1, sample)
            m.transmit()
        sample += 1

    # After the NMT slave has handled the command (subscribers run in order).
    network.subscribe(0x000, on_nmt)
    network.subscribe(0x080, on_sync)
    closed.wait()
    print(f"python node: {syncs} SYNCs handled", file=sys.stderr)


if __name__ == "__main__":
    main()
