"""Unrolled or looped generated code? One hierarchy level's kernel three ways, at 7, 14 and 28 joints.

The kernel is what `formulations/hierarchy.py` does per priority level (without the damping):
J̄ = M⁻¹Jᵀ(JM⁻¹Jᵀ)⁻¹ and N = I − J̄J, for an n×n mass matrix M and a 6-row task Jacobian J.

- unrolled: CasADi SX, the factorizations of `symbolic/linalg.py` expanded scalar by scalar (what
  dcts generates today: straight-line code, as large as the arithmetic);
- CasADi MX: the same with `casadi.solve(..., "ldl")` and dense products, which CasADi's code
  generator emits as calls to its generic (sparse-pattern) routines: loops;
- plain loops: a hand-written C Cholesky, triangular solves and products (what a looped emitter
  over model tables would produce).

Each is compiled with `gcc -O2`; reported: operations (CasADi's count), C source, `.text`, compile
time and the best time per call over interleaved runs (this machine is shared: only the ratios
within one run mean anything). Usage: python scripts/unrolled_vs_looped.py [--sizes 7 14 28]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca

from dcts_spec.symbolic.linalg import spd_inverse

TASK_ROWS = 6
ROUNDS = 7  # interleaved timing rounds; the best of each is kept

INPUTS = r"""
static void fill(int n, int m, double *M, double *J)
{
    unsigned long s = 12345;
    int i, j;
    for (i = 0; i < n; ++i)
        for (j = 0; j <= i; ++j) M[i * n + j] = M[j * n + i] = i == j ? n + 1.0 : 0.5 / (1.0 + (i + j) % 7);
    for (i = 0; i < m * n; ++i) { s = s * 6364136223846793005UL + 1442695040888963407UL; J[i] = (double)(s >> 11) / 9007199254740992.0 - 0.5; }
}
"""

TIMER = r"""
#include <stdio.h>
#include <time.h>
int main(void)
{
    static double M[NN * MM_], J[MM * NN], Jb[NN * MM], N[NN * NN];
    int i, reps = NN < 20 ? 100000 : 10000;
    double sink = 0.0;
    struct timespec a, b;
    fill(NN, MM, M, J);
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (i = 0; i < reps; ++i) { M[0] += 1e-12; CALL; sink += N[1]; }
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%.1f %g\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / reps, sink);
    return 0;
}
"""

LOOPS = r"""
#include <math.h>
static void chol(double *a, int n) /* in place, lower triangle, row-major */
{
    int i, j, k;
    for (j = 0; j < n; ++j) {
        double d = a[j * n + j];
        for (k = 0; k < j; ++k) d -= a[j * n + k] * a[j * n + k];
        d = sqrt(d);
        a[j * n + j] = d;
        for (i = j + 1; i < n; ++i) {
            double v = a[i * n + j];
            for (k = 0; k < j; ++k) v -= a[i * n + k] * a[j * n + k];
            a[i * n + j] = v / d;
        }
    }
}
static void chol_solve(const double *L, int n, double *b, int nrhs) /* b: n x nrhs, row-major */
{
    int i, k, c;
    for (c = 0; c < nrhs; ++c) {
        for (i = 0; i < n; ++i) {
            double v = b[i * nrhs + c];
            for (k = 0; k < i; ++k) v -= L[i * n + k] * b[k * nrhs + c];
            b[i * nrhs + c] = v / L[i * n + i];
        }
        for (i = n - 1; i >= 0; --i) {
            double v = b[i * nrhs + c];
            for (k = i + 1; k < n; ++k) v -= L[k * n + i] * b[k * nrhs + c];
            b[i * nrhs + c] = v / L[i * n + i];
        }
    }
}
void kernel_loops(const double *M, const double *J, double *Jb, double *N)
{
    static double L[NN * NN], X[NN * MM], Lam[MM * MM], Y[MM * NN];
    int i, j, k;
    for (i = 0; i < NN * NN; ++i) L[i] = M[i];
    chol(L, NN);
    for (i = 0; i < NN; ++i) for (j = 0; j < MM; ++j) X[i * MM + j] = J[j * NN + i];
    chol_solve(L, NN, X, MM);
    for (i = 0; i < MM; ++i)
        for (j = 0; j < MM; ++j) {
            double v = 0.0;
            for (k = 0; k < NN; ++k) v += J[i * NN + k] * X[k * MM + j];
            Lam[i * MM + j] = v;
        }
    chol(Lam, MM);
    for (i = 0; i < MM; ++i) for (j = 0; j < NN; ++j) Y[i * NN + j] = X[j * MM + i];
    chol_solve(Lam, MM, Y, NN);
    for (i = 0; i < NN; ++i) for (j = 0; j < MM; ++j) Jb[i * MM + j] = Y[j * NN + i];
    for (i = 0; i < NN; ++i)
        for (j = 0; j < NN; ++j) {
            double v = i == j;
            for (k = 0; k < MM; ++k) v -= Jb[i * MM + k] * J[k * NN + j];
            N[i * NN + j] = v;
        }
}
"""


def casadi_kernel(kind: str, n: int) -> ca.Function:
    """The kernel as a CasADi function of (M, J), M read from its lower triangle."""
    sym = ca.SX.sym if kind == "unrolled" else ca.MX.sym
    M, J = sym("M", n, n), sym("J", TASK_ROWS, n)
    M_sym = ca.tril(M) + ca.tril(M, False).T
    if kind == "unrolled":
        X = ca.mtimes(spd_inverse(M_sym), J.T)
        Jb = ca.mtimes(X, spd_inverse(ca.mtimes(J, X)))
    else:
        X = ca.solve(M_sym, J.T, "ldl")
        Jb = ca.solve(ca.mtimes(J, X), X.T, "ldl").T
    N = (ca.SX.eye(n) if kind == "unrolled" else ca.MX.eye(n)) - ca.mtimes(Jb, J)
    return ca.Function(f"kernel_{kind.replace(' ', '_')}", [M, J], [Jb, N], {"cse": True} if kind == "unrolled" else {})


def build(kind: str, n: int, folder: Path) -> dict:
    """Generate, compile and link one variant; returns its sizes and the path of its timer."""
    folder.mkdir(parents=True, exist_ok=True)
    defines = f"#define NN {n}\n#define MM {TASK_ROWS}\n#define MM_ {n}\n"
    if kind == "plain loops":
        (folder / "k.c").write_text(defines + LOOPS)
        operations = None
        call = "kernel_loops(M, J, Jb, N)"
        header = "void kernel_loops(const double *M, const double *J, double *Jb, double *N);\n"
    else:
        f = casadi_kernel(kind, n)
        generator = ca.CodeGenerator("k.c", {"with_header": True})
        generator.add(f)
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            generator.generate()
        finally:
            os.chdir(cwd)
        operations = f.n_instructions()
        header = (f'#include "k.h"\nstatic casadi_int iw[{max(f.sz_iw(), 1)}]; static double w[{max(f.sz_w(), 1)}];\n'
                  f"static const double *arg[{f.sz_arg()}]; static double *res[{f.sz_res()}];\n")
        call = f"(arg[0] = M, arg[1] = J, res[0] = Jb, res[1] = N, {f.name()}(arg, res, iw, w, 0))"
    start = time.perf_counter()
    subprocess.run(["gcc", "-O2", "-c", "k.c", "-o", "k.o"], cwd=folder, check=True)
    compile_s = time.perf_counter() - start
    (folder / "main.c").write_text(defines + header + INPUTS + TIMER.replace("CALL", call))
    subprocess.run(["gcc", "-O2", "main.c", "k.o", "-o", "timer", "-lm"], cwd=folder, check=True)
    text = int(subprocess.run(["size", "k.o"], cwd=folder, capture_output=True, text=True, check=True).stdout.split("\n")[1].split()[0])
    return {"kind": kind, "n": n, "operations": operations, "source_kB": (folder / "k.c").stat().st_size / 1e3,
            "text_kB": text / 1e3, "compile_s": compile_s, "timer": folder / "timer"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[7, 14, 28])
    args = parser.parse_args()
    kinds = ("unrolled", "CasADi MX", "plain loops")
    with tempfile.TemporaryDirectory() as tmp:
        rows = [build(kind, n, Path(tmp) / f"{kind.replace(' ', '_')}{n}") for n in args.sizes for kind in kinds]
        best = {id(r): float("inf") for r in rows}
        for _ in range(ROUNDS):  # interleaved, so that a change of load hits every variant alike
            for r in rows:
                out = subprocess.run([str(r["timer"])], capture_output=True, text=True, check=True).stdout.split()
                best[id(r)] = min(best[id(r)], float(out[0]))
    print("| n | code | operations | C source | .text | compile (gcc -O2) | time per call | × unrolled |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        unrolled = next(u for u in rows if u["n"] == r["n"] and u["kind"] == "unrolled")
        ops = "—" if r["operations"] is None else f"{r['operations']:,}"
        print(f"| {r['n']} | {r['kind']} | {ops} | {r['source_kB']:.0f} kB | {r['text_kB']:.0f} kB | {r['compile_s']:.1f} s "
              f"| {best[id(r)] / 1e3:.2f} µs | {best[id(r)] / best[id(unrolled)]:.2f} |")


if __name__ == "__main__":
    main()
