"""Set-membership identification: parameter uncertainty intervals (PUI) under bounded
noise, solved as linear programs with HiGHS.

::

    import popup
    from popup import setmembership as sm

    run = popup.read_run("examples/data/lab_run")            # or a SimResult
    s = sm.arx(na=2, nb=2, nk=0, inputs=["q2", "dq2", "q3", "dq3"], output="ee_x", offset=True)
    r = sm.pui(run, s, eps=0.005)                            # |e(t)| <= 5 mm
    r.to_pandas()            # lower, upper, width, center (Chebyshev), minimax, per parameter
    r.plot()                 # intervals as error bars

    s = sm.oe(nb=2, nf=2, nk=0, inputs=["q2", "dq2", "q3", "dq3"], output="ee_x")
    r = sm.oe_pui(run, s, eps=0.005)                         # the thesis's output-error problem

Linear in the parameters (FIR, ARX) — exact
-------------------------------------------
For a model ``y(t) = φ(t)ᵀθ + e(t)`` with ``|e(t)| <= ε`` the feasible parameter set is
the polytope ``FPS = {θ : |y(t) − φ(t)ᵀθ| <= ε, t = 1..N}`` (2N linear inequalities).
Its tightest axis-aligned box, the *parameter uncertainty intervals*, is
``[min θ_i, max θ_i]`` over the FPS: 2p linear programs, solved by HiGHS
(:func:`scipy.optimize.linprog`, ``method="highs"``, the constraint matrix as a
``scipy.sparse`` CSR matrix), in a thread pool (HiGHS releases the GIL). The intervals
are exact to HiGHS's feasibility tolerance (1e-7 of ε on every constraint): every θ that
explains the data within ε lies in them, and every end point is attained by such a θ
(:attr:`PUIResult.witnesses`). Numerics: rows are divided by ε, columns by their largest
magnitude, the variables are re-parameterised so that the constraint matrix has
orthonormal columns (Cholesky QR twice; an ARX on a slowly varying output has cond(Φ) ~
1e7) and shifted to the least-squares fit; all exact changes of variables. Two more LPs:

* the *minimal bound* ``ε_min = min_θ max_t |y(t) − φ(t)ᵀθ|`` (the L∞ / minimax fit;
  its minimiser is :attr:`PUIResult.minimax`). The FPS is empty iff ``ε < ε_min``: then
  :class:`InfeasibleError` says so and gives ``ε_min``;
* the *Chebyshev centre* (centre of the largest ball inside the FPS) as the central
  estimate. The ball is taken in the metric of the regressors, ``‖Φ(θ − θ')/ε‖₂``: free
  of the parameters' units and of any re-parameterisation, and round even when the
  regressors are nearly collinear (where a Euclidean ball in θ would be squeezed to
  nothing by the thinnest direction and its centre would not be central). Every θ with
  ``‖Φ(θ − center)‖₂ <= radius·ε`` is feasible. (Numerically rank-deficient Φ: the
  parameters scaled by their interval half-widths instead; :attr:`PUIResult.center_metric`.)
  The per-coordinate midpoint of the intervals (:attr:`PUIResult.midpoint`) is the
  other classical central estimate (optimal in the worst case per parameter, but not
  always inside the FPS).

Output error (OE) — an approximation, stated
--------------------------------------------
``y(t) = Σ_j B_j(q)/F_j(q) u_j(t) + c + e(t)``, ``|e(t)| <= ε`` is bilinear in the
denominators ``F_j`` and the numerators ``B_j`` (the thesis's problem: second-order
G1..G4 from q2, q̇2, q3, q̇3 to the end-effector x, ε = 5 mm). :func:`oe_pui` does:

1. *Start*: the equation-error (ARX, common denominator A of order max nf) minimax fit;
   ``F_j = A`` for every input, roots reflected inside the unit circle.
2. *Denominator*: sequential linear programming on the true output error. With the
   output linearised in the denominator coefficients (it is exactly linear in the
   numerators and c), one LP gives the minimax step within a trust region; it is kept
   only if the true simulated output error ``max_t |y − ŷ|`` falls (and the ``F_j``
   stay stable). This converges to a *local* minimiser F̂ of
   ``ε_min(F) = min_{B,c} max_t |y − ŷ(F, B, c)|``.
3. *Numerator given F̂* (exact, conditional): with F̂ fixed the model is linear in
   (B, c); its PUI is exact LPs (:attr:`PUIResult.conditional`). It contains the true
   numerator whenever F̂ is the true denominator.
4. *Joint intervals* (first-order): the PUI of the FPS of the model linearised in F
   around F̂ (exact in B and c), with the prior that every F_j is stable (so
   ``|f_ji| <= C(nf_j, i)``, a binomial coefficient). Not guaranteed to contain the
   exact OE-PUI (the exact FPS is not convex); every interval reported is widened to
   contain the conditional intervals and, with ``sweep=M``, every point verified
   feasible in a sweep of denominators: those of the 2p first-order end points and M
   random convex combinations of them, each checked by an exact LP (``ε_min(F) <= ε``)
   and its numerator bounded by exact LPs. The sweep's hull is an *inner*
   approximation of the exact OE-PUI (:attr:`PUIResult.sweep`).

Conventions for OE: the run starts at rest, so the inputs enter as deviations from their
first sample, the filters start from zero, and ``c`` absorbs the output's rest value.
``ε_min`` reported for OE is ``ε_min(F̂)``: an upper bound on the exact OE minimal bound.

Data come from a :class:`~popup.MeasuredRun` (a missing rate channel ``dqN`` is derived
from ``qN`` by central differences, noted), a :class:`~popup.SimResult`, a DataFrame, or
arrays ``(y, u)``. Samples must be uniform in time. Units are those of the channels
(:data:`popup.UNITS`); ε is in the output's unit.

Layout
------
Each module imports only those before it: :mod:`~popup.setmembership.structure` (FIR, ARX,
OE structures), :mod:`~popup.setmembership.data` (identification data, the thesis's inputs
and excitation), :mod:`~popup.setmembership.regression`, :mod:`~popup.setmembership.result`
(:class:`PUIResult`), :mod:`~popup.setmembership.lp` (the linear programs),
:mod:`~popup.setmembership.linear` (:func:`pui`) and :mod:`~popup.setmembership.oe_model`
(:func:`oe_pui`, :func:`identify`).
"""

from __future__ import annotations

from .data import LAB_POSE, THESIS_INPUTS, IdData, iddata, multisine
from .linear import min_bound, pui, pui_linear
from .oe_model import identify, oe_pui, simulate
from .regression import Regression, regressors
from .result import InfeasibleError, PUIResult
from .structure import Structure, arx, fir, oe

__all__ = [
    "Structure",
    "fir",
    "arx",
    "oe",
    "IdData",
    "iddata",
    "Regression",
    "regressors",
    "PUIResult",
    "InfeasibleError",
    "pui_linear",
    "pui",
    "oe_pui",
    "identify",
    "min_bound",
    "simulate",
    "multisine",
    "THESIS_INPUTS",
    "LAB_POSE",
]
