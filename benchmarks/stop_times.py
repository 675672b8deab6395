"""How long a stopped run takes to exit (issue 20): stop a run N times, each at a random moment of one part of it.
MARKERS cycle over the parts (the process start = the imports, the run directory line = start-up, the first [tamer]
line, the first [sleep] line, the last result line = after the summary); the signal (SIGINT, SIGTERM or SIGHUP, at
random) goes out a random 0..D seconds after the marker. Prints one JSON line per run (signal -> exit time, exit code,
summary.json's status and phase, a traceback or not) and the longest time per part. Each run in stops/<i>/.

    python benchmarks/stop_times.py 50 inform_dqn_gridworld.py --tamer-total-timesteps 2500 \
        --tamer-learning-starts 500 --sleep-gradient-steps 2000
    LAST="oracle: return" python benchmarks/stop_times.py 15 inform_sac_pusher.py <tests/test_pusher.py's TINY flags>
"""

import glob
import json
import os
import queue
import random
import signal
import subprocess
import sys
import threading
import time

n, script, flags = int(sys.argv[1]), os.path.abspath(sys.argv[2]), sys.argv[3:]
py = os.environ.get("PY", sys.executable)
random.seed(int(os.environ.get("SEED", "0")))
MARKERS = [
    ("imports", None, 3.0),
    ("startup", "run dir", 0.3),
    ("tamer", "[tamer]", 2.0),
    ("sleep", "[sleep]", 3.0),
    ("after the end", os.environ.get("LAST", "oracle: 19 steps"), 0.05),
]
rows = []
for trial in range(n):
    part, marker, span = MARKERS[trial % len(MARKERS)]
    cwd = os.path.abspath(f"stops/{trial}")
    os.makedirs(cwd, exist_ok=True)
    sig = random.choice([signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
    delay = random.uniform(0, span)

    def defaults():
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, signal.SIG_DFL)

    proc = subprocess.Popen(
        [py, script, *flags],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=defaults,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    lines, err = queue.Queue(), []

    def read_stdout(stream, into):
        for line in stream:
            into.put(line)
        into.put(None)

    ts = [threading.Thread(target=read_stdout, args=(proc.stdout, lines)),
          threading.Thread(target=err.extend, args=(proc.stderr,))]  # fmt: skip
    for t in ts:
        t.start()
    ok = True
    if marker is not None:
        while True:
            line = lines.get(timeout=600)
            if line is None:
                ok = False
                break
            if line.startswith(marker):
                break
    time.sleep(delay)
    sent = None
    if ok and proc.poll() is None:
        sent = time.monotonic()
        proc.send_signal(sig)
    try:
        proc.wait(300)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    ended = time.monotonic()
    for t in ts:
        t.join(30)
    summaries = glob.glob(f"{cwd}/runs/*/summary.json")
    s = json.load(open(summaries[0])) if summaries else {}
    stderr = "".join(err)
    row = {
        "trial": trial,
        "part": part,
        "signal": sig.name,
        "delay_s": round(delay, 3),
        "sent": sent is not None,
        "stop_to_exit_s": round(ended - sent, 3) if sent else None,
        "code": proc.returncode,
        "status": s.get("status"),
        "phase": s.get("phase"),
        "summary_signal": s.get("signal"),
        "traceback": "Traceback" in stderr or "Exception ignored" in stderr,
        "stderr_last": stderr.strip().splitlines()[-1:],
    }
    rows.append(row)
    print(json.dumps(row), flush=True)
sent = [r for r in rows if r["sent"]]
times = sorted(r["stop_to_exit_s"] for r in sent)
print(
    f"{len(sent)} of {n} runs got the signal while running; signal -> exit: longest {times[-1]:.2f}s, median "
    f"{times[len(times) // 2]:.2f}s"
)
for part, _, _ in MARKERS:
    p = [r for r in sent if r["part"] == part]
    if p:
        print(
            f"  {part}: {len(p)} runs, longest {max(r['stop_to_exit_s'] for r in p):.2f}s, summary phases "
            f"{sorted({str(r['phase']) for r in p})}"
        )
bad = [
    r for r in sent if r["code"] not in (128 + signal.Signals[r["signal"]].value, -signal.Signals[r["signal"]].value)
]
print(f"exit code not 128 + signal: {len(bad)} {bad[:3]}")
print(
    f"tracebacks: {sum(r['traceback'] for r in rows)}; runs stopped with a run directory but no summary: "
    f"{sum(1 for r in sent if r['status'] is None and 'no run was made' not in ''.join(r['stderr_last']))}"
)
