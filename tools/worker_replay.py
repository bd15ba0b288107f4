#!/usr/bin/env python3
"""Where a detector worker's CPU time goes, measured on the requests `annotrace annotate` really sends.

Two steps (standard library only; Linux):

  tools/worker_replay.py capture --run RUN --out STREAM [--env pooltool] [--library DIR] [--annotrace BIN]
      Annotates a copy of RUN (RUN itself is not touched) with one worker and records every request
      the Rust side sends that worker, byte for byte, into STREAM. The worker is started through a
      small wrapper named by ANNOTRACE_PYTHON that copies its standard input into a FIFO this script
      reads: the worker runs with RLIMIT_FSIZE=0, so it cannot write a file itself, but it can write
      a pipe.

  tools/worker_replay.py replay STREAM [--worker src/detect/worker.py] [--passes 3] [--share [measured|always]]
      Loads the worker's source without its `main()` (so without the sandbox's lock-down and without
      serving a pipe) and replays STREAM through its own functions, pass after pass, timing each kind
      of request with the thread's CPU clock: loading traces (`P` and `T`), evicting them (`E`),
      compiling detectors (`C`) and running them (`R`). Prints the best pass per kind in ms per trace
      and a SHA-256 of every reply's patterns (as the values they decode to) and printed text (timings
      left out), so a change to worker.py or to a library can be checked for the same output and timed
      in one command. `--share` replays as the workers of `annotate` run (helper results shared
      between a request's detectors, `measured`), `--share always` shares whatever it costs.

The replay runs the worker in this process, not behind the sandbox: only replay streams you captured
from detectors you trust (the detector code is in the stream)."""

import argparse
import gc
import hashlib
import json
import marshal
import os
import shutil
import stat
import struct
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAME = struct.Struct("<I")


def capture(args):
    if not os.path.isdir(args.run):
        sys.exit("worker_replay: %s: no such run folder" % args.run)
    python = shutil.which("python3")
    if python is None:
        sys.exit("worker_replay: no python3 on the PATH")
    # The interpreter the workers would get: python3's real executable, as annotrace resolves it.
    real = subprocess.run([python, "-c", "import sys; print(sys.executable)"],
                          capture_output=True, text=True, check=True).stdout.strip()
    tee = shutil.which("tee") or sys.exit("worker_replay: no tee on the PATH")
    tmp = tempfile.mkdtemp(prefix="worker_replay.")
    try:
        run = os.path.join(tmp, "run")
        shutil.copytree(args.run, run)
        fifo = os.path.join(tmp, "requests")
        os.mkfifo(fifo)
        wrapper = os.path.join(tmp, "python3")
        with open(wrapper, "w") as f:
            # annotrace asks the interpreter for its real executable first: answer with the wrapper,
            # so the workers are started through it.
            f.write("#!/bin/sh\n"
                    'if [ "$1" = -c ] && [ "$2" = "import sys; print(sys.executable)" ]; then\n'
                    '  echo "%s"; exit 0\nfi\n'
                    '"%s" "%s" | exec "%s" "$@"\n' % (wrapper, tee, fifo, real))
        os.chmod(wrapper, os.stat(wrapper).st_mode | stat.S_IXUSR)
        copied = [0]

        def drain():
            # Every worker the run starts writes into the one FIFO; with one worker that is one stream.
            with open(fifo, "rb") as src, open(args.out + ".partial", "wb") as dst:
                while True:
                    b = src.read(1 << 20)
                    if not b:
                        break
                    dst.write(b)
                    copied[0] += len(b)

        reader = threading.Thread(target=drain)
        reader.start()
        cmd = [args.annotrace, "-q", "annotate", "--env", args.env, "--workers", "1", "--run", run]
        if args.library:
            cmd += ["--library", args.library]
        env = dict(os.environ, ANNOTRACE_PYTHON=wrapper)
        done = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL)
        # The FIFO ends when the last writer closes it; if annotate never started a worker, open it
        # for writing once so the reader sees its end.
        if reader.is_alive():
            with open(fifo, "wb"):
                pass
        reader.join()
        # 1: finished, some detector calls failed (their error replies are part of the stream).
        if done.returncode not in (0, 1):
            os.unlink(args.out + ".partial")
            sys.exit("worker_replay: %s exited with %d" % (" ".join(cmd), done.returncode))
        os.replace(args.out + ".partial", args.out)
        print("captured %d bytes of requests into %s" % (copied[0], args.out))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def read_stream(path):
    data = open(path, "rb").read()
    frames, at = [], 0
    while at < len(data):
        if at + 4 > len(data):
            sys.exit("worker_replay: %s: a frame length cut off at byte %d" % (path, at))
        (n,) = FRAME.unpack_from(data, at)
        at += 4
        if at + n > len(data):
            sys.exit("worker_replay: %s: a %d-byte frame cut off at byte %d" % (path, n, at))
        frames.append(data[at:at + n])
        at += n
    return frames


def load_worker(path, share=None):
    """The worker's functions, without running its main() (`share`: as a pool with that
    `share_helpers` starts it)."""
    src = open(path).read().rstrip()
    if not src.endswith("\nmain()"):
        sys.exit("worker_replay: %s does not end with its main() call" % path)
    saved = sys.argv, sys.stdout, sys.stderr
    sys.argv = ["worker", json.dumps({"cpu_seconds": 0, "share_helpers": share or "off"})]
    ns = {"__name__": "annotrace_worker"}
    try:
        exec(compile(src[:-len("main()")], path, "exec"), ns)
    finally:
        # The worker points sys.stdout and sys.stderr at its bounded sinks: take them back.
        sys.argv, sys.stdout, sys.stderr = saved
    return ns


def reply_digest(h, raw, err, head):
    """Adds a call's reply (patterns or error) to the digest, without its wall and CPU times (`head`:
    the worker's `_MARSHAL_HEAD`, which holds them, and the printed text's length). Marshalled patterns
    are hashed as the values they decode to, not as their bytes: marshal flags an object referenced more
    than once, so the same patterns built from shared strings encode differently."""
    if raw is not None and raw[:1] == b"M":
        _, _, n = head.unpack_from(raw, 1)
        start = 1 + head.size
        h.update(raw[start:start + n])  # printed text
        h.update(repr(marshal.loads(raw[start + n:])).encode())
        return
    msg = json.loads(raw) if raw is not None else err
    for d in (msg, msg.get("error") or {}):
        d.pop("wall", None)
        d.pop("cpu", None)
    h.update(json.dumps(msg, sort_keys=True).encode())


def one_pass(worker, frames, share=None):
    ns = load_worker(worker, share)
    clock = time.thread_time
    spent = {"load": 0.0, "evict": 0.0, "compile": 0.0, "run": 0.0}
    traces = calls = 0
    h = hashlib.sha256()
    gc.collect()
    for f in frames:
        kind = f[:1]
        c0 = clock()
        if kind in (b"P", b"T"):
            # As serve() does: no collection while building, the built trace frozen out of later ones.
            gc.disable()
            try:
                key, trace = (ns["load_pool_columns"] if kind == b"P" else ns["load_steps"])(f)
                ns["TRACES"][key] = trace
                del trace
            finally:
                gc.enable()
            gc.freeze()
            spent["load"] += clock() - c0
            traces += 1
        elif kind == b"E":
            for i in json.loads(f[1:]).get("ids", []):
                ns["TRACES"].pop(i, None)
            spent["evict"] += clock() - c0
        elif kind == b"C":
            r = ns["compile_detector"](json.loads(f[1:]))
            spent["compile"] += clock() - c0
            h.update(json.dumps(r, sort_keys=True).encode())
        elif kind == b"R":
            msg = json.loads(f[1:])
            out = []
            begin = ns.get("share_begin")  # as serve() does (worker.py from before sharing has none)
            if begin is not None:
                begin(msg["detectors"])
            for d in msg["detectors"]:
                out.append(ns["run_detector"](d, msg["trace"]))
            if begin is not None:
                ns["share_end"]()
            spent["run"] += clock() - c0
            calls += len(out)
            for raw, err in out:
                reply_digest(h, raw, err, ns["_MARSHAL_HEAD"])
        else:
            sys.exit("worker_replay: unknown request type %r" % kind)
    gc.unfreeze()
    return spent, traces, calls, h.hexdigest()


def replay(args):
    frames = read_stream(args.stream)
    best, digest, traces, calls = None, None, 0, 0
    for _ in range(args.passes):
        spent, traces, calls, d = one_pass(args.worker, frames, args.share)
        if digest is not None and d != digest:
            sys.exit("worker_replay: two passes gave different replies (%s, %s)" % (digest, d))
        digest = d
        best = spent if best is None else {k: min(best[k], spent[k]) for k in spent}
    if not traces:
        sys.exit("worker_replay: %s loads no trace" % args.stream)
    per = {k: 1000 * v / traces for k, v in best.items()}
    print("%d traces, %d detector calls, best of %d passes (CPU ms per trace, Python %s):"
          % (traces, calls, args.passes, sys.version.split()[0]))
    for k in ("load", "evict", "compile", "run"):
        print("  %-8s %7.3f" % (k, per[k]))
    print("  %-8s %7.3f" % ("total", sum(per.values())))
    print("replies sha256 %s" % digest)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture", help="record the requests annotate sends one worker")
    c.add_argument("--run", required=True, help="a run folder holding simulated or imported traces")
    c.add_argument("--out", required=True, help="the stream file to write")
    c.add_argument("--env", default="pooltool")
    c.add_argument("--library", help="a detector library folder (default: the built-in one)")
    c.add_argument("--annotrace", default=shutil.which("annotrace") or "annotrace",
                   help="the annotrace binary (default: annotrace on the PATH)")
    r = sub.add_parser("replay", help="time the worker's parts on a recorded stream")
    r.add_argument("stream")
    r.add_argument("--worker", default=os.path.join(ROOT, "src", "detect", "worker.py"))
    r.add_argument("--passes", type=int, default=3)
    r.add_argument("--share", nargs="?", const="measured", choices=("measured", "always"),
                   help="share helper results between a request's detectors, as annotate's workers "
                        "do (measured, the default) or whatever it costs (always)")
    args = p.parse_args()
    capture(args) if args.cmd == "capture" else replay(args)


if __name__ == "__main__":
    main()
