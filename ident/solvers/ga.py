"""The thesis's genetic algorithm (section 4.2) on the reduced objective of eq. 4.12.

Each candidate is a vector of search variables v = (wn, zeta, p) (eq. 4.1, rad/s, -, rad/s)
inside the box of Fig. 4.1: wn, p in [wn_min / p_min, f_max], zeta in [zeta_min, zeta_max].
One generation t = 1, 2, ...:

1. Crossover (section 4.2.2): the population is paired at random; with probability
   ``crossover_rate`` a pair (v_i, v_j) is replaced by the simulated-binary-crossover
   children of eq. 4.3 (n = 2, one r ~ U(0, 1) per pair)::

       v_i' = (1+a)/2 v_i + (1-a)/2 v_j,   v_j' = (1-a)/2 v_i + (1+a)/2 v_j
       sbx="deb":    a = (2r)^(1/3) if r < 0.5 else (1/(2(1-r)))^(1/3)    (default)
       sbx="thesis": a = (2r)^(1/3) if r < 0.5 else (2(1-r))^(1/3)        (eq. 4.3 as printed)

   otherwise the pair passes unchanged.  Why the default differs from the printed eq. 4.3:
   as printed, a <= 1, so every child lies between its parents and each crossover shrinks
   the population's spread (variance x ~0.8 per crossed generation); with tournament
   selection the population collapses onto one point by generation ~50 and the search then
   relies on the box-scale mutations alone: with 4000 x 500 on the synthetic PID case with
   zeta_max active, 13 of 20 seeds end within 0.1 % of the exact optimum (median 0.08 %,
   worst 0.15 %).  The SBX of the thesis's reference [47] (Deb and Agrawal), whose spread
   factor exceeds 1 for r >= 0.5, keeps the spread: 20 of 20 seeds reach the exact optimum
   to rounding (benchmarks/bench_solvers.py).  Children leaving the box are clamped by
   eq. 4.7 either way.
2. Mutation (section 4.2.3), applied to each child with probability ``mutation_rate``::

       v' = v + R eta N,   R = (v - v_min)/3 if N <= 0 else (v_max - v)/3     (eq. 4.4-4.5)
       eta = exp(tau' N_t + tau N_eta), tau = 1/sqrt(2 sqrt(t)), tau' = 1/sqrt(2 t)  (eq. 4.6)

   N ~ N(0,1) drawn per gene (so each of wn, zeta, p gets its own R), N_eta per candidate,
   N_t once per generation.
3. Constraint checking (section 4.2.4, eq. 4.7): out-of-box genes are clamped to the bound.
   Then (an addition to the thesis, ``canonical=True``) candidates with three real poles
   (zeta >= 1) are re-expressed in the canonical factorisation of
   :func:`ident.model.canonical_search` -- same polynomial, same cost.  Without it the
   population can settle on a fold of the (wn, zeta, p) chart (p equal to a pole of the
   pair), a spurious local minimum next to the complex-pole optimum: on the P-PI synthetic
   case every seed stopped there, 1.5 % above the optimum.
4. Fitness: the reduced cost of eq. 4.12 -- theta_1 from (wn, zeta, p) by eq. 3.14,
   theta_2 by the closed-form least squares of eq. 4.11 -- evaluated for the whole
   population at once.  ``objective="direct"`` evaluates eq. 3.12 on the full Phi instead
   (same numbers, N times the work: for benchmarking the speed-up claimed in section 4.2.5),
   ``objective="gram"`` uses the thesis's literal A, B, Gamma.
5. Selection (section 4.2.5): the ``n_elite`` best (Top Percent, 5 in the thesis) plus
   random tournaments -- pairs drawn at random from the mutated pool, the better one kept --
   for the remaining places; a candidate may be chosen more than once.

Defaults are the thesis's: 4000 candidates, 500 generations, crossover rate 0.5, mutation
rate 0.05, top 5.  The initial population is uniform in the box (section 4.2.1).  The best
candidate ever evaluated is returned; ``details["history"]`` is the best cost of each
generation.  Runs are reproducible for a given ``seed`` (numpy Generator).
"""

from __future__ import annotations

import math
import time

import numpy as np

from core.errors import InputError
from ident.model import Bounds, alphas_from_search, canonical_search
from ident.solvers.common import ReducedObjective, SolverResult, resolve_box

__all__ = ["solve_ga", "OBJECTIVES"]

OBJECTIVES = ("reduced", "gram", "direct")


def solve_ga(Phi: np.ndarray, Y: np.ndarray, bounds: Bounds, *, sample_period: float | None = None,
             population: int = 4000, generations: int = 500, seed: int | np.random.Generator | None = None,
             crossover_rate: float = 0.5, mutation_rate: float = 0.05, n_elite: int = 5,
             objective: str = "reduced", sbx: str = "deb", canonical: bool = True,
             reduced: ReducedObjective | None = None) -> SolverResult:
    """Constrained identification by the genetic algorithm of section 4.2 (module docstring).

    Parameters
    ----------
    Phi : ndarray, shape (N, 8)
        Regressor of eq. 3.11.
    Y : ndarray, shape (N,)
        Actual position, mm.
    bounds : Bounds
        Search box (Hz); ``f_max_hz=None`` needs ``sample_period`` (Nyquist, as the thesis).
    sample_period : float, optional
        T_s in s.
    population, generations : int
        Candidates per generation (even, >= 2 n_elite) and number of generations.
    seed : int or numpy Generator, optional
        Random source; the same seed gives the same result.
    crossover_rate, mutation_rate : float
        Probability that a pair is crossed over / that a child is mutated, in [0, 1].
    n_elite : int
        Number of best candidates always selected (Top Percent).
    objective : {"reduced", "gram", "direct"}
        Fitness evaluation: eq. 4.12 in square-root form, eq. 4.12 literal, or eq. 3.12 direct.
    sbx : {"deb", "thesis"}
        Spread factor of the crossover for r >= 0.5 (module docstring).
    canonical : bool
        Re-express real-pole candidates in the canonical factorisation after clamping
        (module docstring, step 3).
    reduced : ReducedObjective, optional
        Precomputed matrices of eq. 4.12 to reuse.

    Returns
    -------
    SolverResult
        ``solver="ga"``; details hold ``search_variables`` (Hz), ``history`` (best cost per
        generation, mm^2), ``evaluations``, ``seed``, ``objective``, ``fitness_time_s``.
    """
    t0 = time.perf_counter()
    if sbx not in ("deb", "thesis"):
        raise InputError(f"unknown GA sbx variant {sbx!r}; choose deb or thesis")
    if objective not in OBJECTIVES:
        raise InputError(f"unknown GA objective {objective!r}; choose one of {', '.join(OBJECTIVES)}")
    population, generations, n_elite = int(population), int(generations), int(n_elite)
    if population < 4 or population % 2 or n_elite < 0 or n_elite >= population:
        raise InputError(f"GA population must be even and >= 4 with 0 <= n_elite < population, "
                         f"got population={population}, n_elite={n_elite}")
    if generations < 1:
        raise InputError(f"GA generations must be >= 1, got {generations}")
    for name, rate in (("crossover_rate", crossover_rate), ("mutation_rate", mutation_rate)):
        if not 0.0 <= rate <= 1.0:
            raise InputError(f"GA {name} must be in [0, 1], got {rate}")
    lo, hi = resolve_box(bounds, sample_period)
    obj = reduced if reduced is not None else ReducedObjective(Phi, Y)
    if objective == "reduced":
        fitness = obj.cost
    elif objective == "gram":
        A, B, G = obj.gram_form()

        def fitness(wn, zeta, p):
            ai, a1, a2 = alphas_from_search(wn, zeta, p)
            mu = np.stack([np.ones_like(ai), ai, a1, a2], axis=-1)
            return 0.5 * (np.einsum("ni,ij,nj->n", mu, A, mu) + mu @ B + G)
    else:
        fitness = obj.cost_direct

    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    n_pairs = population // 2
    t_fit = 0.0

    def evaluate(V: np.ndarray) -> np.ndarray:
        nonlocal t_fit
        tf = time.perf_counter()
        f = np.asarray(fitness(V[:, 0], V[:, 1], V[:, 2]), dtype=float)
        t_fit += time.perf_counter() - tf
        return np.where(np.isfinite(f), f, np.inf)

    # 4.2.1 initial population, uniform in the box
    V = lo + (hi - lo) * rng.random((population, 3))
    f = evaluate(V)
    i_best = int(np.argmin(f))
    best_v, best_f = V[i_best].copy(), float(f[i_best])
    history = []
    for t in range(1, generations + 1):
        # 4.2.2 crossover: random pairs, SBX with n = 2 (eq. 4.3), one alpha per pair
        perm = rng.permutation(population)
        vi, vj = V[perm[:n_pairs]], V[perm[n_pairs:]]
        r = rng.random(n_pairs)
        upper = 2.0 * (1.0 - r) if sbx == "thesis" else 1.0 / (2.0 * (1.0 - r))
        alpha = np.where(r < 0.5, 2.0 * r, upper) ** (1.0 / 3.0)
        alpha = np.where(rng.random(n_pairs) < crossover_rate, alpha, 1.0)[:, None]
        C = np.concatenate([(1 + alpha) / 2 * vi + (1 - alpha) / 2 * vj,
                            (1 - alpha) / 2 * vi + (1 + alpha) / 2 * vj])
        # 4.2.3 mutation (eq. 4.4-4.6)
        N = rng.standard_normal((population, 3))
        R = np.where(N <= 0.0, (C - lo) / 3.0, (hi - C) / 3.0)
        tau, tau_p = 1.0 / math.sqrt(2.0 * math.sqrt(t)), 1.0 / math.sqrt(2.0 * t)
        eta = np.exp(tau_p * rng.standard_normal() + tau * rng.standard_normal(population))
        mutate = rng.random(population) < mutation_rate
        C = C + (mutate * eta)[:, None] * R * N
        # 4.2.4 constraint checking: clamp to the closest bound (eq. 4.7)
        C = np.clip(C, lo, hi)
        if canonical:
            C = np.column_stack(canonical_search(C[:, 0], C[:, 1], C[:, 2], lo, hi))
        # fitness (eq. 4.12, or eq. 3.12 directly)
        f = evaluate(C)
        # 4.2.5 selection: top n_elite + random tournament
        elite = np.argpartition(f, n_elite)[:n_elite] if n_elite else np.empty(0, dtype=int)
        a = rng.integers(population, size=population - n_elite)
        b = rng.integers(population, size=population - n_elite)
        winners = np.where(f[a] <= f[b], a, b)
        sel = np.concatenate([elite, winners])
        V = C[sel]
        i_best = int(np.argmin(f))
        history.append(float(f[i_best]))
        if f[i_best] < best_f:
            best_v, best_f = C[i_best].copy(), float(f[i_best])

    theta = obj.theta(*best_v)
    details = {"history": history, "best_fitness": best_f, "evaluations": population * (generations + 1),
               "population": population, "generations": generations, "objective": objective,
               "seed": seed if isinstance(seed, (int, type(None))) else "Generator",
               "crossover_rate": crossover_rate, "mutation_rate": mutation_rate, "n_elite": n_elite, "sbx": sbx,
               "canonical": canonical,
               "fitness_time_s": t_fit}
    return obj.result(theta, "ga", bounds, sample_period, tuple(float(x) for x in best_v),
                      time.perf_counter() - t0, details)
