"""Small dense symbolic linear algebra (CasADi SX) for symmetric positive definite matrices.

The factorizations are unrolled element by element, so the generated code is straight-line with no
pivoting and no branches; every diagonal of L is inverted once and then only multiplied by.

Plain Cholesky is used for mass matrices on purpose. It is backward stable without pivoting and its
error is governed by the condition number of the diagonally scaled matrix, so the spread between
base and wrist inertias costs nothing. On 100 random states of the iiwa14, Panda and UR5 (cond(M)
up to 6e3), spd_inverse(M) is within 1.2e-15 (relative to max |M⁻¹|) of the exact rational inverse
of the same M and within 6e-13 of pin.computeMinverse, which itself is the less accurate of the two;
iterative refinement would buy nothing. Featherstone's LTL factorization has the same cost on a
chain (M is dense there) and only pays off on branched trees, where this ordering fills in.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import casadi as ca

# Looped products (`looped_products`): a product of at least this many structural multiplications
# goes through a kernel call; smaller ones stay unrolled (a call copies its operands).
LOOPED_PRODUCT_MIN = 64
_looped: ContextVar[bool] = ContextVar("looped_products", default=False)
# one kernel per (operation, operand sparsities); a process builds a few dozen at most
_kernels: dict[tuple, ca.Function] = {}


@contextmanager
def looped_products() -> Iterator[None]:
    """Within it, `product` and `symmetric_product` of large operands are calls to a never-inlined
    MX kernel, which CasADi's code generator writes once, as its sparse `casadi_mtimes` loops: code
    that grows like the matrices, not like the arithmetic, and is slower than unrolled code
    (dcts_spec/codegen/README.md, "Looped products"). The same numbers for finite inputs."""
    token = _looped.set(True)
    try:
        yield
    finally:
        _looped.reset(token)


def _kernel(operation: str, a: ca.Sparsity, b: ca.Sparsity) -> ca.Function:
    key = (operation, a.size(), b.size(), tuple(a.colind()), tuple(a.row()), tuple(b.colind()), tuple(b.row()))
    kernel = _kernels.get(key)
    if kernel is None:
        x, y = ca.MX.sym("a", a), ca.MX.sym("b", b)
        if operation == "mtimes":
            out = ca.mtimes(x, y)
        else:  # xᵀy on its lower triangle only (mac fills the pattern of its third argument), mirrored
            out = ca.tril2symm(ca.mac(x.T, y, ca.MX.zeros(ca.Sparsity.lower(a.size2()))))
        kernel = ca.Function(f"dcts_{operation}_{len(_kernels)}", [x, y], [out], {"never_inline": True})
        _kernels[key] = kernel
    return kernel


def _looped_call(operation: str, a: ca.SX, b: ca.SX) -> ca.SX | None:
    """Within `looped_products`, the kernel call for a large product (`mtimes`: a b; `gram`: aᵀb,
    symmetric) of operands made sparse (a tree's M has exact zeros: not multiplied); None to
    unroll it."""
    if not _looped.get() or a.is_constant() or b.is_constant():
        return None
    a, b = ca.sparsify(a), ca.sparsify(b)
    if operation == "gram" and a.sparsity() != b.sparsity():  # (the kernel's operands share one pattern)
        union = a.sparsity() + b.sparsity()
        a, b = ca.project(a, union), ca.project(b, union)
    left = ca.DM(a.sparsity(), 1.0)
    counts = ca.mtimes(left.T if operation == "gram" else left, ca.DM(b.sparsity(), 1.0))  # multiplications per entry
    done = ca.tril(counts) if operation == "gram" else counts
    if float(ca.sum1(ca.sum2(done))) < LOOPED_PRODUCT_MIN:
        return None
    # (the result's structural zeros, which the unrolled product has, kept structural)
    return ca.project(_kernel(operation, a.sparsity(), b.sparsity())(a, b), counts.sparsity())


def product(a: ca.SX, b: ca.SX) -> ca.SX:
    """a b: `ca.mtimes`, or a kernel call for a large product within `looped_products`."""
    call = _looped_call("mtimes", a, b)
    return ca.mtimes(a, b) if call is None else call


def _check_square(a: ca.SX, name: str) -> int:
    n, m = a.shape
    if n != m:
        raise ValueError(f"{name} must be square, got {a.shape}")
    return n


def _factor(a: ca.SX) -> tuple[ca.SX, list[ca.SX]]:
    """Cholesky factor L of A and the inverses 1 / L_jj it was built with, a column at a time (one
    product per column: the same sums, in the same order, as an entry at a time, and a tree's
    structural zeros stay structural)."""
    n = _check_square(a, "A")
    low = ca.SX(n, n)
    inv: list[ca.SX] = []
    for j in range(n):
        row = low[j, :j]
        low[j, j] = ca.sqrt(a[j, j] - ca.sumsqr(row))
        inv.append(1 / low[j, j])
        if j + 1 < n:
            low[j + 1 :, j] = (a[j + 1 :, j] - ca.mtimes(low[j + 1 :, :j], row.T)) * inv[j]
    return low, inv


def _diagonal_inverses(low: ca.SX) -> list[ca.SX]:
    return [1 / low[i, i] for i in range(low.shape[0])]


def _lower_inverse(low: ca.SX, inv: list[ca.SX]) -> ca.SX:
    """L⁻¹ (lower triangular) row by row, given inv[i] = 1 / L_ii."""
    n = low.shape[0]
    out = ca.SX(n, n)
    for i in range(n):
        out[i, i] = inv[i]
        if i:
            out[i, :i] = -ca.mtimes(low[i, :i], out[:i, :i]) * inv[i]
    return out


def cholesky(a: ca.SX) -> ca.SX:
    """Lower-triangular L with A = L Lᵀ, reading only the lower triangle of A (SPD, not checked)."""
    return _factor(a)[0]


def cholesky_solve(low: ca.SX, b: ca.SX) -> ca.SX:
    """X with L Lᵀ X = B: forward substitution L Y = B, then back substitution Lᵀ X = Y."""
    n = _check_square(low, "L")
    if b.shape[0] != n:
        raise ValueError(f"B must have {n} rows, got {b.shape}")
    inv = _diagonal_inverses(low)
    y = ca.SX(*b.shape)
    for i in range(n):
        y[i, :] = (b[i, :] - ca.mtimes(low[i, :i], y[:i, :])) * inv[i]
    x = ca.SX(*b.shape)
    for i in reversed(range(n)):
        x[i, :] = (y[i, :] - ca.mtimes(low[i + 1 :, i].T, x[i + 1 :, :])) * inv[i]
    return x


def triangular_inverse(low: ca.SX) -> ca.SX:
    """L⁻¹ of a lower-triangular L (itself lower triangular)."""
    _check_square(low, "L")
    return _lower_inverse(low, _diagonal_inverses(low))


def _mirrored(n: int, lower_row: Callable[[int], ca.SX]) -> ca.SX:
    """The symmetric n × n matrix whose row i up to its diagonal is lower_row(i) (1 × (i + 1)), its
    upper triangle the same expressions: exactly symmetric, each entry computed once."""
    out = ca.SX(n, n)
    for i in range(n):
        row = lower_row(i)
        out[i, : i + 1] = row
        out[:i, i] = row[:, :i].T
    return out


def spd_inverse(a: ca.SX) -> ca.SX:
    """A⁻¹ = L⁻ᵀ L⁻¹ of an SPD matrix, computed on the lower triangle so it is exactly symmetric."""
    n = _check_square(a, "A")
    linv = _lower_inverse(*_factor(a))
    # (L⁻ᵀ L⁻¹)_ij = Σ_k≥i (L⁻¹)_ki (L⁻¹)_kj for j ≤ i, since L⁻¹ is lower triangular
    return _mirrored(n, lambda i: ca.mtimes(linv[i:, i].T, linv[i:, : i + 1]))


def symmetric_product(a: ca.SX, b: ca.SX) -> ca.SX:
    """aᵀb where it is known to be symmetric (GᵀG, Aᵀ(M A), J (M⁻¹Jᵀ)): its lower triangle, mirrored.

    CasADi does not see that Σₖ aₖᵢbₖⱼ and Σₖ aₖⱼbₖᵢ are equal, so `mtimes(a.T, b)` computes both
    triangles: twice the work of a Gram matrix (the posture's least squares was 38 % of the QP
    data at 16 joints), and a result symmetric only up to rounding. Within `looped_products`, a
    kernel call if it is large."""
    n = a.shape[1]
    if b.shape != a.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    call = _looped_call("gram", a, b)
    if call is not None:
        return call
    return _mirrored(n, lambda i: ca.mtimes(a[:, i].T, b[:, : i + 1]))  # (Σₖ aₖᵢbₖⱼ, j ≤ i)


def null_space_basis(a: ca.SX) -> ca.SX:
    """Orthonormal basis (n × (n − m)) of the null space of a full-row-rank A (m × n), m < n.

    Householder QR of Aᵀ, unrolled: Aᵀ = Q R, and the last n − m columns of Q span null(A).
    Householder QR is backward stable without pivoting; each reflector's sign is chosen to avoid
    cancellation, and a zero column (A rank deficient) gives the identity reflector, not NaN.
    Q = H₀ ⋯ H_{m−1} is never formed: its last columns are the reflectors applied to [0; I] from
    the last one back, (n − m)/n of the work (a quarter for 12 task rows on 16 joints).
    """
    m, n = a.shape
    if m >= n:
        raise ValueError(f"A must have fewer rows than columns, got {a.shape}")
    r = ca.SX(a.T)
    reflectors = []
    for k in range(m):
        x = r[k:, k]
        alpha = -ca.if_else(x[0] >= 0, 1.0, -1.0) * ca.norm_2(x)
        v = ca.vertcat(x[0] - alpha, x[1:])
        scale = 2.0 / (ca.sumsqr(v) + 1e-300)
        r[k:, k:] = r[k:, k:] - scale * ca.mtimes(v, ca.mtimes(v.T, r[k:, k:]))
        reflectors.append((v, scale))
    basis = ca.SX(n, n - m)
    basis[m:, :] = ca.SX.eye(n - m)
    for k in reversed(range(m)):
        v, scale = reflectors[k]
        basis[k:, :] = basis[k:, :] - scale * ca.mtimes(v, ca.mtimes(v.T, basis[k:, :]))
    return basis
