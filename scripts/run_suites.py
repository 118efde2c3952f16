"""Run the test suites of several Blender venvs side by side (`make test`).

    python scripts/run_suites.py --jobs 2 "5.0.1 whole suite=.venv/bin/python" \
        "5.2.3 whole suite=.venv52/bin/python" -- tests

Each run is ``<python> -m pytest <args>`` (a run named "... smoke ..." adds ``-m smoke``) with a
temporary folder of its own (``--basetemp``) and pytest's cache off, so runs that share the
checkout do not write the same files.  At most ``--jobs`` run at once (two cores: two suites
take about as long as the slower one alone); each run's output goes to a log that is printed
whole, under its name, when the run ends, followed by a summary of every run.  The exit status
is 0 only if every run passed.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="runs at once (default 2)")
    ap.add_argument("runs", nargs="+", help='"NAME=PYTHON" for each run, then -- and the pytest arguments')
    args, rest = ap.parse_known_args(argv)
    runs = [r for r in args.runs if "=" in r]
    pytest_args = [r for r in args.runs if "=" not in r] + [r for r in rest if r != "--"]
    if not runs:
        ap.error("no NAME=PYTHON run given")
    return args.jobs, [tuple(r.split("=", 1)) for r in runs], pytest_args


def start(name, python, pytest_args, tmp: Path):
    """The run's process, its log file and its start time."""
    slug = "".join(ch if ch.isalnum() else "_" for ch in name)
    log = open(tmp / f"{slug}.log", "w+", encoding="utf-8")
    cmd = [python, "-m", "pytest", *pytest_args, "-p", "no:cacheprovider", f"--basetemp={tmp / slug}"]
    if "smoke" in name:
        cmd += ["-m", "smoke"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, env=env)
    print(f"== started: {name} ({' '.join(cmd[:3])} ...)", flush=True)
    return proc, log, time.monotonic()


def main(argv=None) -> int:
    jobs, runs, pytest_args = parse(sys.argv[1:] if argv is None else argv)
    results = []
    with tempfile.TemporaryDirectory(prefix="bolus-suites-") as t:
        tmp = Path(t)
        waiting, running = list(runs), []
        while waiting or running:
            while waiting and len(running) < max(1, jobs):
                name, python = waiting.pop(0)
                running.append((name, *start(name, python, pytest_args, tmp)))
            time.sleep(0.5)
            for item in list(running):
                name, proc, log, t0 = item
                if proc.poll() is None:
                    continue
                running.remove(item)
                log.seek(0)
                print(f"\n== {name}: exit {proc.returncode} after {time.monotonic() - t0:.0f} s", flush=True)
                sys.stdout.write(log.read())
                log.close()
                results.append((name, proc.returncode, time.monotonic() - t0))
    print("\n== summary")
    for name, rc, dt in results:
        print(f"   {'passed' if rc == 0 else 'FAILED'}  {name}  ({dt:.0f} s)")
    return 0 if all(rc == 0 for _, rc, _ in results) else 1


if __name__ == "__main__":
    sys.exit(main())
