"""A misbehaving external SLAM program for the tests: `python fake_program.py MODE STEP`.

Dead reckoning (pose = odometry, no map) that, at step STEP, does what MODE says: garbage
(bytes that are no msgpack), print (a stray line on stdout), stall (sleeps), crash (a message
on stderr, exit code 3), sigkill (kills itself), seq (answers another step), nan (a NaN pose),
mapreq (says the map changed, and answers the request for it with garbage); mode version3
answers the hello with version 3; mode ok misbehaves never. Mode gate asks for GMapping's
gate (linear_update 0.25 m, angular_update 10 rad) in its ready, answers with the map -> odom
correction GATE_T, and logs "got SEQ trail K" on stderr for each step (K skipped steps before
it); mode badgate asks for a gate with a negative linear_update. Modes due1 and due2 speak
version 1 or 2, say every scan changed the map, log "due SEQ true|false" (whether the step
carried map_due) and "map request" on stderr, and answer a map request with an unchanged map."""

from __future__ import annotations

import math
import os
import signal
import struct
import sys
import time

import msgpack

GATE_T = (1.0, 2.0, math.pi / 2)  # [m, m, rad] the map -> odom correction of mode gate


def send(out, message: dict) -> None:
    payload = msgpack.packb(message, use_bin_type=True)
    out.write(struct.pack(">I", len(payload)) + payload)
    out.flush()


def misbehave(mode: str, out, seq: int) -> bool:
    """Do MODE's thing at the step; whether the answer is sent already."""
    if mode == "garbage":
        out.write(struct.pack(">I", 3) + b"\xc1\xc1\xc1")
    elif mode == "print":
        out.write(b"hello from a stray print\n")
    elif mode == "stall":
        time.sleep(60)
    elif mode == "crash":
        print("matcher: segmentation fault in scan 42", file=sys.stderr, flush=True)
        sys.exit(3)
    elif mode == "sigkill":
        os.kill(os.getpid(), signal.SIGKILL)
    elif mode == "seq":
        send(out, {"type": "estimate", "seq": seq + 1, "pose": [0.0, 0.0, 0.0]})
    elif mode == "mapreq":
        send(out, {"type": "estimate", "seq": seq, "pose": [0.0, 0.0, 0.0], "updated": True})
    elif mode == "nan":
        send(out, {"type": "estimate", "seq": seq, "pose": [0.0, float("nan"), 0.0]})
    else:
        return False
    out.flush()
    return True


def main() -> int:
    mode, at = sys.argv[1], int(sys.argv[2])
    stdin, out = sys.stdin.buffer, sys.stdout.buffer
    while len(header := stdin.read(4)) == 4:
        msg = msgpack.unpackb(stdin.read(struct.unpack(">I", header)[0]), raw=False)
        if msg["type"] == "hello":
            version = {"version3": 3, "due2": 2}.get(mode, 1)
            send(out, {"type": "hello", "protocol": "mapqual-slam", "version": version})
        elif msg["type"] == "config":
            print(f"fake program: mode {mode} at step {at}", file=sys.stderr, flush=True)
            if mode == "gate":
                send(out, {"type": "ready", "gate": {"linear_update": 0.25, "angular_update": 10}})
            elif mode == "badgate":
                send(out, {"type": "ready", "gate": {"linear_update": -1, "angular_update": 1}})
            else:
                send(out, {"type": "ready"})
        elif msg["type"] == "step":
            if msg["seq"] == at and misbehave(mode, out, msg["seq"]):
                continue
            if mode == "gate":
                trail = len(msg.get("trail", b"")) // 32  # rows of 4 float64
                print(f"got {msg['seq']} trail {trail}", file=sys.stderr, flush=True)
                x, y, th = msg["odom"]
                c, s = math.cos(GATE_T[2]), math.sin(GATE_T[2])
                pose = [GATE_T[0] + c * x - s * y, GATE_T[1] + s * x + c * y, GATE_T[2] + th]
                send(out, {"type": "estimate", "seq": msg["seq"], "pose": pose,
                           "T_map_odom": list(GATE_T)})  # fmt: skip
                continue
            if mode in ("due1", "due2"):
                due = "true" if msg.get("map_due") else "false"
                print(f"due {msg['seq']} {due}", file=sys.stderr, flush=True)
                send(out, {"type": "estimate", "seq": msg["seq"], "pose": msg["odom"],
                           "updated": True})  # fmt: skip
                continue
            send(out, {"type": "estimate", "seq": msg["seq"], "pose": msg["odom"]})
        elif msg["type"] == "map" and mode in ("due1", "due2"):
            print("map request", file=sys.stderr, flush=True)
            send(out, {"type": "map", "map": None})
        elif msg["type"] == "map" and mode == "mapreq":
            out.write(struct.pack(">I", 1) + b"\xc1")
            out.flush()
        elif msg["type"] == "bye":
            return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
