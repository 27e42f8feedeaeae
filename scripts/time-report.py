#!/usr/bin/env python3
"""Where a build and a test run spent their time, from the files they leave behind.

  scripts/time-report.py [BUILD_DIR] [--top N]

Reads BUILD_DIR/.ninja_log (each compile and link step's start and end) and CTest's record of
the last run (BUILD_DIR/Testing/Temporary/LastTest.log: each test's wall time) and prints:
  - the build's wall time and the summed step time by kind (compile, link, other);
  - the targets whose compiles took longest (summed over their translation units);
  - the N slowest tests, and the tests' summed time by executable (ctest prefix).
Times in seconds. Ninja runs several steps at once, so summed step time exceeds wall time.
"""
import argparse
import collections
import os
import re
import sys


def ninja_steps(build):
    """[(start_ms, end_ms, output)] of the last build recorded in .ninja_log (v5)."""
    path = os.path.join(build, ".ninja_log")
    steps = {}
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                continue
            parts = line.rstrip("\n").split("\t")
            if len(parts) < 4:
                continue
            start, end, output = int(parts[0]), int(parts[1]), parts[3]
            steps[output] = (start, end, output)  # a rebuilt output's last entry wins
    return list(steps.values())


def target_of(output):
    m = re.search(r"CMakeFiles/([^/]+)\.dir/", output)
    if m:
        return m.group(1)
    return os.path.basename(output)


def test_times(build):
    """{test name: seconds} from CTest's LastTest.log."""
    path = os.path.join(build, "Testing", "Temporary", "LastTest.log")
    if not os.path.exists(path):
        return {}
    times = {}
    name = None
    with open(path, errors="replace") as f:
        for line in f:
            m = re.match(r'^\d+/\d+ Test: (\S+)$', line.strip())
            if m:
                name = m.group(1)
                continue
            m = re.match(r'^"(\S+)" end time: ', line)
            if m:
                continue
            m = re.match(r'^Test time = +([0-9.]+) sec', line)
            if m and name:
                times[name] = float(m.group(1))
                name = None
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("build", nargs="?", default=os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "..", "build"))
    ap.add_argument("--top", type=int, default=10)
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    try:
        steps = ninja_steps(build)
    except OSError as e:
        print(f"time-report: no build record in {build}: {e}", file=sys.stderr)
        return 1
    if steps:
        wall = (max(s[1] for s in steps) - min(s[0] for s in steps)) / 1000.0
        kinds = collections.Counter()
        by_target = collections.Counter()
        links = collections.Counter()
        for start, end, out in steps:
            t = (end - start) / 1000.0
            if out.endswith(".o"):
                kinds["compile"] += t
                by_target[target_of(out)] += t
            elif out.startswith("bin/") or out.endswith(".a"):
                kinds["link"] += t
                links[os.path.basename(out)] += t
            else:
                kinds["other"] += t
        print(f"build: {len(steps)} steps over {wall:.0f} s wall; summed step time: " +
              ", ".join(f"{k} {v:.0f} s" for k, v in kinds.most_common()))
        print(f"  compile time by target (top {args.top}):")
        for target, t in by_target.most_common(args.top):
            print(f"    {t:7.1f} s  {target}")
        print(f"  links (top {min(args.top, 5)}):")
        for target, t in links.most_common(min(args.top, 5)):
            print(f"    {t:7.1f} s  {target}")
    times = test_times(build)
    if times:
        total = sum(times.values())
        print(f"tests: {len(times)} in the last ctest run, {total:.0f} s summed")
        print(f"  slowest {args.top}:")
        for name, t in sorted(times.items(), key=lambda kv: -kv[1])[:args.top]:
            print(f"    {t:7.1f} s  {name}")
        by_exe = collections.Counter()
        for name, t in times.items():
            by_exe[name.split(".")[0]] += t
        print(f"  by executable (top {args.top}):")
        for exe, t in by_exe.most_common(args.top):
            print(f"    {t:7.1f} s  {exe}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
