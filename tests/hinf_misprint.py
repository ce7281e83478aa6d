"""The paper's misprinted LMIs, built outside the library for the tests that
document the trap.

Peixoto et al. print ``P_{3,j}`` in ``Phi_21`` where the proof needs
``P_{3,l}`` (``P(alpha_{k+1})``): see the module documentation of
:mod:`lpvest.design`. :func:`printed_lmis` is the library's ``lmi_blocks`` with
that one index as printed; :func:`printed_phi21` puts it in the library's
place for the duration of a ``with`` block, so that :func:`lmi_matrices`,
:class:`HinfProgram` (compiled inside the block) and its eigenvalue check all
use the printed blocks.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import pytest

from lpvest.design import _lmis, _program
from lpvest.design._lmis import LMIBlock, _q_next, _q_now, _xg_rows


def printed_lmis(
    data: Sequence[Mapping[str, Any]],
    var: Mapping[str, Any],
    a: Any,
    b: Any,
    *,
    robust: bool,
    bmat: Callable[..., Any],
) -> list[LMIBlock]:
    """``lmi_blocks`` with the paper's ``P_{3,j}`` in ``Phi_21`` (the same
    arguments, blocks and order)."""
    n = len(data)
    nx, nw = data[0]["Bw"].shape
    nz = data[0]["Cz"].shape[0]
    n_rest = 2 * nx + nz + nw

    def vertex_vars(j: int) -> dict[str, Any]:
        f = 0 if robust else j
        out = {k: var[k][j] for k in ("X1", "X2", "X3", "X4", "X5", "X6")}
        out.update({k: var[k][f] for k in ("H", "Af", "Bf", "Cf", "Df")})
        return out

    K: dict[tuple[int, int], Any] = {}
    for i in range(n):
        for j in range(n):
            L = bmat(_xg_rows(data[i], vertex_vars(j), a, b))
            K[i, j] = L + L.T
    Qc = [_q_now(var["P1"][j], var["P2"][j], var["P3"][j], var["delta"], nz, nw, bmat) for j in range(n)]

    def qn(j: int, nxt: int) -> Any:
        # P(alpha_{k+1}) at vertex nxt, but with P_{3,j} as printed (the misprint)
        return _q_next(var["P1"][nxt], var["P2"][nxt], var["P3"][j], n_rest, bmat)

    out: list[LMIBlock] = []
    for l in range(n):  # noqa: E741 - the paper's index
        for i in range(n):
            out.append(LMIBlock(f"Phi_{i + 1}{i + 1}{l + 1}", i, i, l, qn(i, l) + Qc[i] + K[i, i]))
            for j in range(i + 1, n):
                phi_ijl = qn(j, l) + Qc[j] + K[i, j]
                phi_jil = qn(i, l) + Qc[i] + K[j, i]
                label = f"Phi_{i + 1}{j + 1}{l + 1} + Phi_{j + 1}{i + 1}{l + 1}"
                out.append(LMIBlock(label, i, j, l, phi_ijl + phi_jil))
    return out


@contextlib.contextmanager
def printed_phi21() -> Iterator[None]:
    """Within the block, the library builds the printed (misprinted) LMIs."""
    with pytest.MonkeyPatch.context() as mp:
        # lmi_matrices (and the eigenvalue check) looks the blocks up in _lmis, HinfProgram in _program
        mp.setattr(_lmis, "lmi_blocks", printed_lmis)
        mp.setattr(_program, "lmi_blocks", printed_lmis)
        yield
