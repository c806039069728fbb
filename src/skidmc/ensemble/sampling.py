"""Designs on the unit hypercube and their map to scene inputs.

Reproducibility is by construction: every random stream comes from one
:class:`numpy.random.SeedSequence` per study seed, keyed by what is drawn, never by who draws it.

* ``mc``: independent uniforms in fixed blocks of :data:`MC_BLOCK` samples; block b uses the
  stream ``SeedSequence(seed, spawn_key=(STREAM_MC, b))``. Sample i is therefore the same for
  any worker count, chunk size or sample count n (a larger n only appends samples).
* ``lhs``: :class:`scipy.stats.qmc.LatinHypercube` over the whole study, drawn once up front
  (stratification needs n); it holds n x d floats in memory.
* ``sobol``: scrambled :class:`scipy.stats.qmc.Sobol`; any slice is computed on its own with
  ``fast_forward`` and equals the same rows of the full sequence, and the first n points of a
  larger n are the same.
* ``saltelli``: SALib's Saltelli/Sobol' design (:func:`SALib.sample.sobol.sample`, scrambled),
  N (2d + 2) rows (or N (d + 2) without second order), drawn once up front, with the column
  order of :attr:`skidmc.ensemble.study.Study.keys` (the ``problem`` of :func:`salib_problem`).

A design row u in [0, 1)^d becomes inputs in three steps (:func:`transform`): the Gaussian
copula of the study's correlations (normal scores z = Phi^-1(u) mixed by the Cholesky factor of
the correlation matrix, back through Phi), truncation to [U_TAIL, 1 - U_TAIL] (the quantiles the
study checked against the physical range), and each distribution's ``ppf`` (times the scene's
nominal value for relative distributions). A sampled rate at the reference temperature gives the
prefactor Z = k_ref exp(E/R / T_ref) with the sample's own E/R. A key uncertain at two levels
(:attr:`skidmc.ensemble.study_model.StudyScene.factors`) is its epistemic value (or nominal
value) times its aleatory factor, drawn in the factor's own design column. Every step acts row
by row, with no reduction across rows, so a row's inputs do not depend on which other rows share
its batch.
"""

from __future__ import annotations

import numbers

import numpy as np
from scipy.special import ndtr, ndtri
from scipy.stats import qmc

from skidmc.ensemble.study import RATE_AT_REFERENCE, U_TAIL, Study
from skidmc.ensemble.study_model import aleatory_factor_column, prefactor_from_rate

__all__ = [
    "MC_BLOCK",
    "NestedDesign",
    "StudySampler",
    "UniformDesign",
    "salib_problem",
    "seed_sequence",
    "transform",
]

#: Samples per independent random stream of the ``mc`` design. Fixed: changing it changes every
#: ``mc`` result, so it is part of the file format (recorded in the result's attributes).
MC_BLOCK = 1024

# spawn_key roots of the streams, one per use of the seed.
STREAM_MC, STREAM_LHS, STREAM_SOBOL, STREAM_SALTELLI = 0, 1, 2, 3


def seed_sequence(seed: int, *stream: int) -> np.random.SeedSequence:
    """The study's seed normaliser: the SeedSequence of `seed` for the stream `stream`.

    Parameters
    ----------
    seed : int
        Study seed, an integer >= 0 (0 is a seed like any other).
    *stream : int
        Stream key, e.g. ``(STREAM_MC, block)``; equal to spawning children in that order.

    Returns
    -------
    numpy.random.SeedSequence

    Raises
    ------
    ValueError
        `seed` is not an integer >= 0 (None is refused: a study must be reproducible).
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed = {seed!r}: expected an integer >= 0")
    return np.random.SeedSequence(int(seed), spawn_key=tuple(int(s) for s in stream))


def _qmc_engine(cls, d: int, rng: np.random.Generator):
    """A scrambled scipy.stats.qmc engine driven by `rng`."""
    try:
        return cls(d, scramble=True, rng=rng)
    except TypeError:  # scipy < 1.15 calls the same argument `seed`
        return cls(d, scramble=True, seed=rng)


class UniformDesign:
    """Rows of a design on [0, 1)^d, computed slice by slice.

    Parameters
    ----------
    method : {"mc", "lhs", "sobol", "saltelli"}
    n : int
        Samples (``saltelli``: base samples N).
    d : int
        Dimension (number of uncertain inputs).
    seed : int
        Study seed.
    second_order : bool
        ``saltelli`` only.

    Attributes
    ----------
    n_rows : int
        Number of rows of the whole design.
    """

    def __init__(self, method: str, n: int, d: int, seed: int, second_order: bool = True):
        if method not in ("mc", "lhs", "sobol", "saltelli"):
            raise ValueError(f"method = {method!r}: expected mc, lhs, sobol or saltelli")
        self.method, self.n, self.d, self.seed = method, int(n), int(d), seed
        self.second_order = bool(second_order)
        seed_sequence(seed)  # validate early
        if method == "saltelli":
            self.n_rows = self.n * (2 * self.d + 2 if self.second_order else self.d + 2)
        else:
            self.n_rows = self.n
        self._full: np.ndarray | None = None  # lhs, saltelli: drawn once
        self._block: tuple[int, np.ndarray] | None = None  # mc: last block generated

    def _rng(self, *stream: int) -> np.random.Generator:
        return np.random.default_rng(seed_sequence(self.seed, *stream))

    def rows(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start:stop`` of the design, shape (stop - start, d), values in [0, 1)."""
        if not 0 <= start <= stop <= self.n_rows:
            raise IndexError(f"rows {start}:{stop} outside the design's 0:{self.n_rows}")
        if self.method == "mc":
            return self._mc_rows(start, stop)
        if self.method == "sobol":
            engine = _qmc_engine(qmc.Sobol, self.d, self._rng(STREAM_SOBOL))
            if start:
                engine.fast_forward(start)
            return engine.random(stop - start)
        if self._full is None:
            self._full = self._draw_full()
        return self._full[start:stop]

    def _mc_rows(self, start: int, stop: int) -> np.ndarray:
        out = np.empty((stop - start, self.d))
        i = start
        while i < stop:
            b = i // MC_BLOCK
            if self._block is None or self._block[0] != b:
                self._block = (b, self._rng(STREAM_MC, b).random((MC_BLOCK, self.d)))
            j = min(stop, (b + 1) * MC_BLOCK)
            out[i - start:j - start] = self._block[1][i - b * MC_BLOCK:j - b * MC_BLOCK]
            i = j
        return out

    def _draw_full(self) -> np.ndarray:
        if self.method == "lhs":
            return _qmc_engine(qmc.LatinHypercube, self.d, self._rng(STREAM_LHS)).random(self.n)
        from SALib.sample import sobol as saltelli_sample

        problem = {"num_vars": self.d, "names": [f"x{i}" for i in range(self.d)],
                   "bounds": [[0.0, 1.0]] * self.d}
        return saltelli_sample.sample(problem, self.n, calc_second_order=self.second_order,
                                      scramble=True, seed=self._rng(STREAM_SALTELLI))


def salib_problem(study: Study) -> dict:
    """SALib ``problem`` dict of a study's design columns (for ``SALib.analyze.sobol``)."""
    return {"num_vars": len(study.keys), "names": list(study.keys),
            "bounds": [[0.0, 1.0]] * len(study.keys)}


class NestedDesign:
    """A second-order design: outer epistemic draws x inner aleatory draws, by row index.

    Row ``r`` is epistemic draw ``e = r // n_inner`` and aleatory draw ``a = r % n_inner``: its
    epistemic columns are row ``e`` of the outer design, its aleatory columns row ``a`` of the
    inner design. Every epistemic draw meets the same aleatory draws (common random numbers): the
    curves of two epistemic draws then differ by what the epistemic inputs do, not by sampling
    noise of the aleatory ones. Rows depend only on their index, so a sample is the same whatever
    the chunking, worker count or interruption.

    Parameters
    ----------
    method : str
        Design of both levels (``mc``, ``lhs`` or ``sobol``).
    n_outer, n_inner : int
        Epistemic draws, aleatory draws per epistemic draw.
    outer_columns, inner_columns : sequence of int
        Columns (of the study's keys) of each level; together every column once.
    seed : int
        Study seed; the two levels use independent streams of it.
    """

    def __init__(self, method: str, n_outer: int, n_inner: int, outer_columns, inner_columns,
                 seed: int) -> None:
        if method == "saltelli":
            raise ValueError("method = 'saltelli': a nested (epistemic x aleatory) design takes "
                             "mc, lhs or sobol")
        self.outer_columns = np.asarray(outer_columns, dtype=int)
        self.inner_columns = np.asarray(inner_columns, dtype=int)
        self.d = self.outer_columns.size + self.inner_columns.size
        self.n_outer, self.n_inner = int(n_outer), int(n_inner)
        # Independent streams: the outer design from seed's child 0, the inner from child 1.
        child = np.random.SeedSequence(seed).spawn(2)
        self.outer = UniformDesign(method, self.n_outer, self.outer_columns.size,
                                   int(child[0].generate_state(1)[0]))
        self.inner = UniformDesign(method, self.n_inner, self.inner_columns.size,
                                   int(child[1].generate_state(1)[0]))
        self.n_rows = self.n_outer * self.n_inner

    def rows(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start:stop``, shape (stop - start, d), values in [0, 1)."""
        if not 0 <= start <= stop <= self.n_rows:
            raise IndexError(f"rows {start}:{stop} outside the design's 0:{self.n_rows}")
        index = np.arange(start, stop)
        outer_index, inner_index = np.divmod(index, self.n_inner)
        out = np.empty((index.size, self.d))
        if index.size:
            e0, e1 = int(outer_index[0]), int(outer_index[-1]) + 1
            a0, a1 = int(inner_index.min()), int(inner_index.max()) + 1
            out[:, self.outer_columns] = self.outer.rows(e0, e1)[outer_index - e0]
            out[:, self.inner_columns] = self.inner.rows(a0, a1)[inner_index - a0]
        return out


class StudySampler:
    """Draws a study's inputs slice by slice.

    Parameters
    ----------
    study : Study
        A validated study; its design gives method, n and seed. With both aleatory and
        epistemic inputs and ``design.n_epistemic`` > 0 the design nests (:class:`NestedDesign`).

    Attributes
    ----------
    design : UniformDesign or NestedDesign
    n_rows : int
        Samples per scene.
    """

    def __init__(self, study: Study) -> None:
        self.study = study
        spec = study.design
        n_epistemic = getattr(spec, "n_epistemic", 0)
        if n_epistemic:
            epistemic = [i for i, k in enumerate(study.keys) if study.kind(k) == "epistemic"]
            aleatory = [i for i, k in enumerate(study.keys) if study.kind(k) != "epistemic"]
            self.design = NestedDesign(spec.method, n_epistemic, spec.n, epistemic, aleatory,
                                       spec.seed)
        else:
            self.design = UniformDesign(spec.method, spec.n, len(study.keys), spec.seed,
                                        spec.second_order)
        self.n_rows = self.design.n_rows

    def draw(self, start: int, stop: int) -> list[dict[str, np.ndarray]]:
        """Inputs of samples ``start:stop`` for every scene (see :func:`transform`)."""
        return transform(self.study, self.design.rows(start, stop))


def _copula(study: Study, u: np.ndarray) -> np.ndarray:
    """Impose the study's Gaussian-copula correlations on uniform columns, row by row."""
    if not study.correlations:
        return u
    names = sorted({k for c in study.correlations for k in c.keys},
                   key=study.keys.index)
    cols = [study.keys.index(k) for k in names]
    r = np.eye(len(names))
    for c in study.correlations:
        a, b = names.index(c.keys[0]), names.index(c.keys[1])
        r[a, b] = r[b, a] = c.rho
    z = correlate_normal_scores(ndtri(u[:, cols]), np.linalg.cholesky(r))
    out = u.copy()
    out[:, cols] = ndtr(z)
    return out


def correlate_normal_scores(z: np.ndarray, cholesky: np.ndarray) -> np.ndarray:
    """Gaussian copula: independent normal scores z (rows) -> z L^T, row by row.

    Parameters
    ----------
    z : ndarray, shape (m, d)
        Independent standard normal scores [-].
    cholesky : ndarray, shape (d, d)
        Lower Cholesky factor L of the copula's correlation matrix.

    Returns
    -------
    ndarray, shape (m, d)
        Normal scores with correlation L L^T [-]. Shared by :func:`transform` and
        :class:`skidmc.analysis.rare_events.GaussianCopulaTransform`.
    """
    out = np.empty_like(z)
    for j in range(z.shape[1]):
        # An explicit sum rather than z @ chol.T: BLAS may order a matrix product's sums by the
        # batch's shape, and a sample must not depend on which batch it travels in.
        zj = cholesky[j, 0] * z[:, 0]
        for k in range(1, j + 1):
            zj = zj + cholesky[j, k] * z[:, k]
        out[:, j] = zj
    return out


def transform(study: Study, u: np.ndarray) -> list[dict[str, np.ndarray]]:
    """Map design rows to the inputs of every scene of a study.

    Parameters
    ----------
    study : Study
    u : ndarray, shape (m, d)
        Rows in [0, 1]^d, columns in the order of ``study.keys`` (a caller with its own points,
        e.g. an adaptive rare-event method, may pass any rows here).

    Returns
    -------
    list of dict
        One dict per scene (``study.scenes`` order): key -> values, shape (m,), in SI units, for
        every uncertain key of the scene; with
        :data:`~skidmc.ensemble.study.RATE_AT_REFERENCE` also the derived
        ``kinetics.prefactor`` [1/s].
    """
    u = np.atleast_2d(np.asarray(u, dtype=float))
    if u.shape[1] != len(study.keys):
        raise ValueError(f"u has {u.shape[1]} columns, the study {len(study.keys)} keys")
    u = np.clip(_copula(study, u), U_TAIL, 1.0 - U_TAIL)
    out = []
    for sc in study.scenes:
        values = {key: dist.ppf(u[:, study.keys.index(key)], sc.nominal(key))
                  for key, dist in sc.uncertain.items()}
        for key, factor in sc.factors.items():  # a key uncertain at two levels: level x factor
            level = values[key] if key in values else sc.nominal(key)
            values[key] = level * factor.frozen.ppf(u[:, study.keys.index(
                aleatory_factor_column(key))])
        if RATE_AT_REFERENCE in values:
            t_act = values.get("kinetics.activation_temperature",
                               sc.nominal("kinetics.activation_temperature"))
            t_ref = sc.uncertain[RATE_AT_REFERENCE].reference_temperature
            values["kinetics.prefactor"] = prefactor_from_rate(values[RATE_AT_REFERENCE], t_act,
                                                                t_ref)
        out.append(values)
    return out
