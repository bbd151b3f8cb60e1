"""The C flags a bundle ships with, in one place: its Makefile's and CMakeLists.txt's defaults,
and the build `dcts bench` times (it links the bundle's own objects).

No -march=native: a bundle is copied to and cross-compiled for other machines. No -ffast-math:
the step checks its inputs and outputs for NaN and Inf, which -ffinite-math-only would remove.
"""

from __future__ import annotations

# Measured on TALOS's torso and arms (16 joints, 1.9 MB of C; callgrind, and the best of 9 runs
# of 3000 closed-loop states on a loaded 2-core machine): -O2 529 k instructions a step, 53.9 µs;
# -O2 -fno-math-errno 534 k, 55.0 µs; -O3 -fno-math-errno 521 k, 54.7 µs; -O2 -march=native
# 53.1 µs (the 18 % for native did not reproduce). None is measurably faster: -O2 ships.
HOST_OPTIMIZATION: tuple[str, ...] = ("-O2",)
C_WARNINGS: tuple[str, ...] = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")


def flags_text(flags: tuple[str, ...]) -> str:
    """The flags as a Makefile or CMake writes them."""
    return " ".join(flags)
