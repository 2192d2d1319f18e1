#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Sets up, builds and runs every test. Exits non-zero if any step or test fails.
#  1. Release build (-Werror), all GoogleTest suites through CTest.
#  2. ThreadSanitizer build of the solver/analysis hand-over tests (label "concurrency") and of
#     run control (label "control": solver, analysis and render threads, pause/stop/changes, and
#     the service soak: random transitions from six clients over real sockets).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh -DSPHLES_WERROR=ON
# Tests run two at a time on two cores: OpenMP threads that spin while waiting would steal the
# cores from each other (small runs were seen 30x slower), so waiting threads sleep.
export OMP_WAIT_POLICY=PASSIVE
(cd build && ctest --output-on-failure --parallel "$(nproc)" --no-tests=error --timeout 1200)

# libgomp is not instrumented, so OpenMP teams would give false reports: the TSan run checks
# the std::thread hand-over with one OpenMP thread per thread.
echo "== ThreadSanitizer: concurrency tests =="
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSPHLES_TSAN=ON \
  -DSPHLES_BUILD_BENCH=OFF -DSPHLES_WERROR=ON > build-tsan.configure.log 2>&1 ||
  { cat build-tsan.configure.log; exit 1; }
cmake --build build-tsan --parallel "$(nproc)" --target pipeline_tests control_tests soak_tests
(cd build-tsan && OMP_NUM_THREADS=1 \
  TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PWD/../tests/tsan.supp" \
  ctest --output-on-failure --parallel "$(nproc)" -L "concurrency|control" --no-tests=error \
  --timeout 1200)
