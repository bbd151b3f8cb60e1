"""The C flags a bundle ships with, in one place: its Makefile's and CMakeLists.txt's defaults,
and the build `dcts bench` times (it links the bundle's own objects).

No -march=native: a bundle is copied to and cross-compiled for other machines. No -ffast-math:
the step checks its inputs and outputs for NaN and Inf, which -ffinite-math-only would remove.
"""

from __future__ import annotations

from ..controller import LOOPED_PRODUCTS_FROM

# The controller's own C (the cascade around DAQP, the checks) at -O3: on the bench spec (3,000
# closed-loop states, five alternating runs) the median step took 3.62 µs against 3.87 µs at -O2
# (-6.5 %; its loops over rows and variables are unrolled and vectorized; no reassociation, so the
# same numbers). The QP data, one straight-line function, gain nothing from it (3.63 µs with both
# at -O3) and take longer to compile: they get QP_DATA_OPTIMIZATION (below). Measured before on
# the whole bundle of TALOS's torso and arms (16 joints; callgrind, best of 9 runs): -O2 529 k
# instructions a step, 53.9 µs; -O3 -fno-math-errno 521 k, 54.7 µs; -O2 -march=native 53.1 µs.
HOST_OPTIMIZATION: tuple[str, ...] = ("-O3",)
QP_DATA_OPTIMIZATION: tuple[str, ...] = ("-O2",)
# The controller's own C in the Cortex-M7 images (the Makefile's ARM_CONTROLLER_OPT): -Os, for
# flash. On the bench spec 12.0 kB of code instead of 15.5 kB at the -O2 of the rest of the image,
# and the same answers bit for bit (every output of 804 steps on qemu, golden vectors and perturbed
# copies): it is ISO C99, where gcc fuses no a*b + c (-ffp-contract=off) at any -O. Not DAQP (gnu99:
# its fused operations differ between -O2 and -Os, and so did its answers), not the QP data
# (straight-line code: 79.9 kB at -Os against 77.9 kB at -O2). The host keeps HOST_OPTIMIZATION.
FIRMWARE_CONTROLLER_OPTIMIZATION: tuple[str, ...] = ("-Os",)
# What firmware projects commonly build with, besides -Wall -Wextra: a bundle compiles cleanly
# under it (-Werror), so that it can join such a build as it is.
C_WARNINGS: tuple[str, ...] = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion",
                               "-Wmissing-prototypes", "-Wstrict-prototypes", "-Wshadow")
# DAQP with the flags of its Python package (daqp's setup.py), so that both runtimes compute alike:
# the Makefile's and CMakeLists.txt's (which built it at -O2 before).
DAQP_OPTIMIZATION: tuple[str, ...] = ("-O3", "-fassociative-math", "-fno-signed-zeros", "-fno-trapping-math")
# The QP data are one straight-line function (CasADi's, unrolled), whose compile time and memory
# grow with its operations. TALOS's 28 joints (83 k operations; gcc 12, stores without null
# checks): -O2 36 s and 1.0 GB, -O1 13 s and 0.50 GB, for 7.9 % more instructions in the QP data
# and 1.4 % a step (callgrind, 2,000 closed-loop steps). At 7 joints -O1 costs 12 % of the QP
# data's instructions and saves ~1 s. Splitting the function into 7 files instead cut the peak
# memory to 0.29 GB but not the time (2 cores: 36 s of wall time for 64 s of CPU).
QP_DATA_O1_FROM = 40_000  # QP-data operations from which the QP data are compiled with -O1
# Larger still, -O1 too takes minutes: the projector baseline's closed form on a 16-joint hand
# (235 k operations, 5.6 MB of C) took gcc 280 s at -O1, 29 s and 2.9 GB at -O0. dcts's own QP
# data stay below 100 k operations up to 29 joints. From this size on the control law's large
# products are looped (controller.LOOPED_PRODUCTS_FROM, the same number). No bundle beyond
# controller.MAX_QP_DATA_OPERATIONS.
QP_DATA_O0_FROM = LOOPED_PRODUCTS_FROM


def qp_data_optimization(operations: int) -> tuple[str, ...]:
    """The optimization flags of the QP data's C file (the rest of the bundle: HOST_OPTIMIZATION)."""
    if operations >= QP_DATA_O0_FROM:
        return ("-O0",)
    return ("-O1",) if operations >= QP_DATA_O1_FROM else QP_DATA_OPTIMIZATION


def flags_text(flags: tuple[str, ...]) -> str:
    """The flags as a Makefile or CMake writes them."""
    return " ".join(flags)
