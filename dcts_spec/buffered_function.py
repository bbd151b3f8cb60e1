"""A CasADi Function evaluated into numpy arrays allocated once.

Calling a `ca.Function` on numpy arrays converts every input to a DM and every output back
(`np.array(DM)`): for the QP data (5 inputs, 16 outputs) that costs more than the evaluation
itself. Through CasADi's FunctionBuffer the same virtual machine reads the inputs from, and
writes the outputs into, numpy arrays it was given once: the same numbers, bit for bit, without
the conversions.

The outputs are row-major, as `np.array(DM)` gives them: CasADi writes a matrix column by
column, so the buffer is filled by the function of the transposed outputs (the same expressions,
only their order differs). A column-major A would make numpy's `A @ x` add in another order, and
the lexicographic solve's decisions amplified those 1e-16 differences to 5e-11.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


class BufferedFunction:
    """`function` (dense inputs and outputs) called on numpy arrays.

    A call returns the same dict of output arrays every time, overwritten by the next call: a
    caller that keeps a value past that copies it. The outputs lie one after the other in one
    array, so that consecutive ones can be checked at once (`span`). Not for several threads at
    once."""

    def __init__(self, function: ca.Function):
        for kind, count, sparsity in (("input", function.n_in(), function.sparsity_in),
                                      ("output", function.n_out(), function.sparsity_out)):
            for i in range(count):
                if not sparsity(i).is_dense():
                    raise ValueError(f"{function.name()}: {kind} {i} is sparse (densify it)")
        symbols = function.sx_in() if function.is_a("SXFunction") else function.mx_in()
        transposed = ca.Function(f"{function.name()}_row_major", symbols,
                                 [ca.transpose(out) for out in function.call(symbols)])
        self._buffer, self._evaluate = transposed.buffer()
        self._inputs = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        ends = np.cumsum([0] + [function.nnz_out(i) for i in range(function.n_out())])
        self._block = np.zeros(ends[-1])
        flat_outputs = [self._block[ends[i]:ends[i + 1]] for i in range(function.n_out())]
        self._ends = {function.name_out(i): (int(ends[i]), int(ends[i + 1])) for i in range(function.n_out())}
        for i, array in enumerate(self._inputs):
            self._buffer.set_arg(i, memoryview(array))
        for i, array in enumerate(flat_outputs):
            self._buffer.set_res(i, memoryview(array))
        self.outputs = {function.name_out(i): array.reshape(function.size_out(i))
                        for i, array in enumerate(flat_outputs)}

    def span(self, first: str, last: str) -> np.ndarray:
        """The outputs `first` to `last` (in the function's order), flat, as one array (a view)."""
        return self._block[self._ends[first][0]:self._ends[last][1]]

    def __call__(self, *inputs: np.ndarray) -> dict[str, np.ndarray]:
        for target, value in zip(self._inputs, inputs, strict=True):
            target[:] = value
        self._evaluate()
        return self.outputs
