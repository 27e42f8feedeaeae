#!/usr/bin/env bash
# Static analysis: Debian's clang-tidy with the checked-in .clang-tidy over every C++ source of
# the project (core, services, clients, tests, bench), two at a time per core. Any finding fails
# (.clang-tidy: WarningsAsErrors '*'); each is printed as file:line:col: warning: ... [check].
#
# It reads the compile commands of a tree of its own (./build-tidy: the normal build's
# configure, without precompiled headers, which clang cannot read from g++). There each
# target's sources are compiled in batches (CELL_UNITY_BUILD), so clang-tidy parses the heavy
# headers once per batch instead of once per file; a source's findings are reported once, under
# its own path. Only the generated IDL headers are built there, not the project.
#
#   scripts/tidy.sh                 # everything
#   scripts/tidy.sh core/vision     # the batches holding sources whose path matches (a regex)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/install-deps.sh"
build="${CELL_TIDY_BUILD_DIR:-$root/build-tidy}"
if [ ! -f "$build/build.ninja" ]; then
  cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCELL_WERROR=ON \
    -DCELL_PCH=OFF >/dev/null
fi
cmake --build "$build" --target cell_idl >/dev/null

# The translation units: every project source of the compile database (a batch file stands
# for the sources it includes). A path argument keeps the batches that hold a matching source.
mapfile -t units < <(python3 - "$build" "$root" "${1:-}" <<'EOF'
import json, os, re, sys
build, root, pattern = sys.argv[1], sys.argv[2], sys.argv[3]
for entry in json.load(open(os.path.join(build, "compile_commands.json"))):
    f = entry["file"]
    if not f.endswith((".cpp", ".cxx")):
        continue                      # the generated IDL C sources
    if "/Unity/" in f:
        sources = re.findall(r'#include "([^"]+)"', open(f).read())
    else:
        sources = [f]
    sources = [s for s in sources if s.startswith(root + "/") and "/build" not in s[len(root):]]
    if sources and (not pattern or any(re.search(pattern, s[len(root) + 1:]) for s in sources)):
        print(f)
EOF
)
echo "tidy.sh: clang-tidy $(clang-tidy --version | sed -n 's/.*version \([0-9.]*\).*/\1/p') on ${#units[@]} translation units" >&2
# Findings in the project's own files only: not in /usr/include (whose paths hold .../core/...)
# nor in the build's generated headers.
filter="^${root}/(core|services|clients|tests|bench)/"
out="$(mktemp /tmp/cell-tidy-XXXXXX.log)"
rc=0
# Progress: a line every 10 units (run-clang-tidy prints each unit's command line when done).
run-clang-tidy -quiet -p "$build" -j "$(nproc)" -header-filter "$filter" \
  -extra-arg=-Wno-unknown-warning-option "${units[@]}" 2>&1 | sed -u 's/\x1b\[[0-9;]*m//g' |
  tee "$out" | awk -v total="${#units[@]}" '/^clang-tidy/ { if (++done % 10 == 0) {
    printf "tidy.sh: %d of %d units\n", done, total > "/dev/stderr"; fflush() } }' ||
  rc=$?
# run-clang-tidy prints each unit's command and warnings; keep the findings and their context.
grep -E '^/.*: (warning|error): ' "$out" | sort -u > "$out.findings" || true
n=$(wc -l < "$out.findings")
if [ "$rc" -ne 0 ] || [ "$n" -gt 0 ]; then
  grep -vE '^(clang-tidy|\[[0-9]+/[0-9]+\]|[0-9]+ warnings? (and [0-9]+ errors? )?generated|Suppressed [0-9]+ warnings|Use -header-filter|Error while processing)' "$out" >&2 || true
  echo "tidy.sh: $n finding(s) (exit $rc); the list:" >&2
  sed "s|^${root}/||" "$out.findings" >&2
  rm -f "$out" "$out.findings"
  exit 1
fi
rm -f "$out" "$out.findings"
echo "tidy.sh: no finding"
