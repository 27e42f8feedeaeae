#!/usr/bin/env bash
# The sanitizer run: a second build of the libraries, services, clients and their unit tests
# with AddressSanitizer and UndefinedBehaviorSanitizer (-Og, the test code -O0, frame pointers;
# CELL_SANITIZE in CMakeLists.txt, CELL_TEST_CODE_OPT in cmake/CellTargets.cmake) in
# ./build-asan, then every unit test. The multi-process tests under tests/ and the benchmarks
# are not in this build (they run on the normal one, scripts/test.sh).
#
# Every process a test starts is instrumented too; each writes its reports to a file of its
# own under $CELL_SANITIZER_LOGS (a fresh directory). The run fails when a test fails or when
# any report was written, and prints the reports.
#
#   scripts/sanitize.sh [ctest args, e.g. -R task_service]
#   scripts/sanitize.sh --build-only      # the build alone (.ci/run: beside the suite)
#   scripts/sanitize.sh --no-build [...]  # the tests alone, on the build as it is
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
build="${CELL_ASAN_BUILD_DIR:-$root/build-asan}"
mode=all
case "${1:-}" in
  --build-only) mode=build; shift ;;
  --no-build) mode=test; shift ;;
esac
if [ "$mode" != test ]; then
  "$root/scripts/install-deps.sh"
  # scripts/build.sh's configure (Ninja, RelWithDebInfo, warnings as errors), with the
  # sanitizers.
  CELL_BUILD_DIR="$build" "$root/scripts/build.sh" -DCELL_SANITIZE=ON \
    -DCELL_INTEGRATION_TESTS=OFF -DCELL_BUILD_BENCH=OFF
fi
if [ "$mode" = build ]; then
  exit 0
fi
if [ ! -f "$build/CTestTestfile.cmake" ]; then
  echo "sanitize.sh: no sanitizer build in $build (run scripts/sanitize.sh without --no-build)" >&2
  exit 2
fi

logs="$(mktemp -d /tmp/cell-sanitizer-XXXXXX)"
export CELL_SANITIZER_LOGS="$logs"
# halt_on_error: the first report ends the process (and so fails its test). Leaks are reports.
export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:log_path=$logs/asan:strict_string_checks=1:detect_invalid_pointer_pairs=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:log_path=$logs/ubsan"
# OpenCV tries every video backend on a name none other opens; its gphoto2 backend then lists
# the USB devices through Debian's libgphoto2 port plugin, which leaks the list (2500 objects a
# test, in a plugin unloaded before LeakSanitizer reports, so no suppression can name it). That
# backend is off here: no camera of the cell is a gphoto2 still camera.
export OPENCV_VIDEOIO_PRIORITY_GPHOTO2=0
rc=0
# Four slots per core, as scripts/test.sh: most unit tests wait on real time; the ones that
# compute hold more slots (PROCESSORS, cmake/CellTargets.cmake).
ctest --test-dir "$build" --output-on-failure -j "$((4 * $(nproc)))" --timeout 600 "$@" || rc=$?

reports=$(find "$logs" -type f | sort)
if [ -n "$reports" ]; then
  echo "sanitize.sh: $(echo "$reports" | wc -l) sanitizer report(s):" >&2
  for f in $reports; do
    echo "----- $f" >&2
    cat "$f" >&2
  done
  rc=1
else
  echo "sanitize.sh: no sanitizer report (ASan, UBSan, LeakSanitizer)"
fi
rm -rf "$logs"
exit "$rc"
