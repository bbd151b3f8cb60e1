"""The C flags a bundle ships with, in one place: its Makefile's and CMakeLists.txt's defaults,
and the build `dcts bench` times (it links the bundle's own objects).

No -march=native: a bundle is copied to and cross-compiled for other machines. No -ffast-math:
the step checks its inputs and outputs for NaN and Inf, which -ffinite-math-only would remove.
"""

from __future__ import annotations

# -fno-math-errno: sqrt and friends compile to the instruction instead of a call that may set
# errno (the results are IEEE's either way; nothing reads errno).
HOST_OPTIMIZATION: tuple[str, ...] = ("-O2", "-fno-math-errno")
C_WARNINGS: tuple[str, ...] = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")


def flags_text(flags: tuple[str, ...]) -> str:
    """The flags as a Makefile or CMake writes them."""
    return " ".join(flags)
