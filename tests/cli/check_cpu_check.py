#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""A native build of sphles on a processor without its extensions (app/cpu_check.hpp).

Runs `sphles version` under QEMU's user-mode emulator as a plain x86-64 processor (`-cpu
qemu64`: SSE2, no AVX): a build compiled with -march=native for this machine must stop at once
with exit status 1 and a message naming the extensions it lacks (those of the build that qemu64
does not have), instead of dying of an illegal instruction (status 132). A build that needs no
extension (SPHLES_NATIVE=OFF, Debug) must run there. Under `-cpu max` the emulator has AVX2
but no AVX-512: a build that needs AVX-512 is refused naming it.
Usage: check_cpu_check.py QEMU SPHLES "FEATURES" (the build's list, cmake/NativeCpuFeatures.cmake)
"""
import subprocess
import sys



def run(qemu, cpu, sphles):
    done = subprocess.run([qemu, "-cpu", cpu, sphles, "version"], capture_output=True, text=True,
                          timeout=120)
    return done.returncode, done.stdout, done.stderr


def main():
    qemu, sphles, features = sys.argv[1], sys.argv[2], sys.argv[3].split()
    rc, out, err = run(qemu, "qemu64", sphles)
    if not features:
        if rc != 0 or not out.startswith("sphles "):
            sys.exit(f"a build without extensions failed on qemu64: rc {rc}\n{out}\n{err}")
        print("no extensions required: sphles runs on qemu64")
        return
    if rc != 1 or not err.startswith("sphles: this processor lacks "):
        sys.exit(f"qemu64: expected rc 1 and the missing extensions, got rc {rc}:\n{out}\n{err}")
    named = err[len("sphles: this processor lacks "):].split(",")[0].split()
    if not named or any(f not in features for f in named):
        sys.exit(f"qemu64: the message names {named}, not a subset of the build's {features}")
    for expected in ("avx2", "avx512f"):
        if expected in features and expected not in named:
            sys.exit(f"qemu64 has no {expected}, but the message does not name it: {err}")
    if "-DSPHLES_NATIVE=OFF" not in err or out:
        sys.exit(f"qemu64: the message does not say how to build for this processor: {err}")
    print(f"qemu64: refused with rc 1 naming {' '.join(named)}")
    if "avx512f" in features:
        rc, out, err = run(qemu, "max", sphles)
        if rc != 1 or "avx512f" not in err.split(",")[0] or "avx2" in err.split(",")[0].split():
            sys.exit(f"-cpu max (AVX2, no AVX-512): expected a refusal naming avx512f and not "
                     f"avx2, got rc {rc}:\n{err}")
        print("max: refused naming the AVX-512 extensions only")


if __name__ == "__main__":
    main()
