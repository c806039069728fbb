"""The handling hazard under a calibration's posterior: epistemic draws from posterior.nc.

A hazard study with a ``[hazard.posterior]`` table (:class:`skidmc.ensemble.study_schema.
PosteriorSpec`) takes the epistemic loop's draws of its ``[hazard.epistemic]`` inputs from the
stored posterior of a calibration study (:mod:`skidmc.workflows.calibration`) instead of a
Latin hypercube over their priors:

* the posterior is ``results/<calibration name>/posterior.nc`` (where ``skidmc run`` of the
  calibration study writes it, relative to the working directory), or a ``.nc`` file named
  directly (relative to the hazard study file);
* the calibration stores each parameter's *physical* value (ArviZ InferenceData, group
  ``posterior``, dims chain x draw), or the *factor* on its scene's nominal value where the
  prior is ``relative`` (its ``summary`` attribute lists ``relative`` and ``nominal`` per
  parameter); the normal scores it sampled are not stored. A factor is turned into the physical
  value [SI] (factor x nominal), and the rate at the reference temperature is carried from the
  calibration's reference temperature to the hazard's through each draw's own activation
  temperature (one-step Arrhenius) where the two differ;
* the n draws are equally spaced over the stored draws flattened in (chain, draw) order: the
  draws at indices floor((i + 1/2) N / n), i = 0..n-1, of N. Each draw is a whole row of the
  posterior, so the inputs' joint distribution (their correlation) is kept;
* every ``[hazard.epistemic]`` input must be in the posterior (the study is refused otherwise,
  naming the input and the posterior); the posterior's other parameters are not used, each with
  the reason the summary states (:func:`unused_reason`).

The pooled estimate of the study stays over the priors (its importance sampler needs a
density, which a set of stored draws does not give); the posterior's P per accident is the mean
over the posterior draws of P(theta_j), with a Student-t interval over the draws
(:func:`posterior_probability`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import warnings
from pathlib import Path

import numpy as np
from scipy import stats

from skidmc.ensemble.study_model import RATE_AT_REFERENCE, StudyError

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

__all__ = ["PosteriorDraws", "posterior_path", "posterior_probability", "read_posterior",
           "thinned_indices", "unused_reason", "with_posterior_sha"]

#: Where the study names its posterior (error messages).
KEY = "hazard.posterior.calibration"


@dataclasses.dataclass(frozen=True)
class PosteriorDraws:
    """Draws of a hazard study's epistemic inputs taken from a calibration's posterior.

    Attributes
    ----------
    calibration : str
        The calibration study's name (the ``study_name`` attribute of the file).
    path : str
        The posterior file read.
    sha256 : str
        SHA-256 of its bytes (part of the hazard run's identity: a new posterior is a new run).
    completed : str
        When the calibration finished (its ``completed`` attribute).
    keys : tuple of str
        The hazard's epistemic inputs, in study order.
    draws : dict
        Input -> its value at each thinned draw [SI], shape (n,).
    indices : numpy.ndarray
        The thinned draws' indices into the flattened (chain, draw) posterior.
    stored : int
        Draws stored (chains x draws).
    posterior : dict
        Input -> its value at every stored draw [SI], shape (stored,).
    prior : dict
        Input -> the calibration's stored prior draws [SI] (empty if the file keeps none).
    unused : dict
        The posterior's other parameters -> why the hazard does not use them.
    """

    calibration: str
    path: str
    sha256: str
    completed: str
    keys: tuple[str, ...]
    draws: dict[str, np.ndarray]
    indices: np.ndarray
    stored: int
    posterior: dict[str, np.ndarray]
    prior: dict[str, np.ndarray]
    unused: dict[str, str]


def thinned_indices(stored: int, n: int) -> np.ndarray:
    """n equally spaced indices into `stored` draws: floor((i + 1/2) stored / n).

    Parameters
    ----------
    stored : int
        Draws available (>= n).
    n : int
        Draws wanted (>= 1).

    Returns
    -------
    numpy.ndarray of int
    """
    if n < 1 or n > stored:
        raise ValueError(f"n = {n}: expected 1 <= n <= {stored} (the draws stored)")
    return ((np.arange(n) + 0.5) * stored / n).astype(np.int64)


def posterior_path(study) -> Path:
    """The posterior file a hazard study names (``[hazard.posterior] calibration``).

    Parameters
    ----------
    study : HazardStudy
        With ``posterior`` set.

    Returns
    -------
    Path
        A ``.nc`` named directly (relative to the study file), else
        ``results/<calibration name>/posterior.nc`` of the calibration study named.

    Raises
    ------
    StudyError
        The calibration study file is missing or is not a calibration study, or its posterior
        has not been computed.
    """
    value = study.posterior
    base = Path(study.file).parent if Path(study.file).is_file() else Path(".")
    named = base / value
    if named.suffix == ".nc":
        path = named
        hint = "the posterior file named does not exist"
    else:
        if not named.is_file():
            raise StudyError(study.file, KEY, value, f"no such calibration study file ({named})")
        try:
            doc = tomllib.loads(named.read_text(encoding="utf-8"))
            name = doc["study"]["name"] if doc["study"]["kind"] == "calibration" else None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError):
            name = None
        if not isinstance(name, str):
            raise StudyError(study.file, KEY, value, f"{named} is not a calibration study "
                             "([study] kind = \"calibration\" with a name)")
        path = Path("results") / name / "posterior.nc"
        hint = f"run the calibration first: skidmc run {named}"
    if not path.is_file():
        raise StudyError(study.file, KEY, value, f"no posterior at {path}: {hint}")
    return path


def unused_reason(name: str) -> str:
    """Why a parameter of the posterior is not an input of the hazard study."""
    if name.startswith("discrepancy["):
        return ("the model discrepancy of one of the report's targets (a factor on that "
                "target's H_c): it belongs to the report's targets, not to the hazard's floors")
    if name.startswith("friction.population"):
        return ("a hyperparameter of the report's finishes' friction population: the hazard's "
                "floors keep their own friction distributions ([[hazard.surface]])")
    if name.startswith("mu[") or name.startswith("target."):
        return "a property of one of the report's targets, not of the hazard's floors"
    return ("learned by the calibration but not an epistemic input of this hazard study: held "
            "at the scene's value, as in the study over the priors (list it in "
            "[hazard.epistemic] to take its posterior draws)")


def _reference_temperature(prior_text: str) -> float | None:
    """The calibration prior's reference temperature of the rate [K] (None: not sampled)."""
    from skidmc.ensemble.study import parse_study

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prior = parse_study(prior_text, "<the calibration's prior study>")
    for sc in prior.scenes:
        d = sc.uncertain.get(RATE_AT_REFERENCE)
        if d is not None:
            return d.reference_temperature
    return None


def read_posterior(study, n: int | None = None) -> PosteriorDraws:
    """The epistemic draws of a hazard study from its calibration's posterior.

    Parameters
    ----------
    study : HazardStudy
        With ``posterior`` set (``[hazard.posterior]``).
    n : int, optional
        Draws wanted (default: the study's ``epistemic_draws``).

    Returns
    -------
    PosteriorDraws

    Raises
    ------
    StudyError
        No posterior file, a file that is not a calibration's posterior, an epistemic input
        the posterior lacks, or more draws asked than stored: naming
        ``hazard.posterior.calibration`` and its value.
    """
    import arviz as az

    path = posterior_path(study)
    n = study.estimator.epistemic_draws if n is None else n
    data = path.read_bytes()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            idata = az.from_netcdf(str(path), engine="h5netcdf")
        post = idata.posterior
        summary = json.loads(idata.attrs["summary"])
        params = {p["name"]: p for p in summary["parameters"]}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise StudyError(study.file, KEY, study.posterior,
                         f"{path} is not a calibration's posterior (ArviZ InferenceData with a "
                         f"posterior group and a summary attribute): {exc}") from None
    names = list(post.data_vars)
    missing = [k for k in study.epistemic_keys if k not in post.data_vars or k not in params]
    if missing:
        raise StudyError(study.file, KEY, study.posterior,
                         f"its posterior ({path}) holds no draws of {missing[0]} "
                         f"([hazard.epistemic.\"{missing[0]}\"]); it holds {', '.join(names)}: "
                         "calibrate that input, or take it out of [hazard.epistemic]")
    chains, length = post.sizes["chain"], post.sizes["draw"]
    stored = chains * length
    if n > stored:
        raise StudyError(study.file, KEY, study.posterior,
                         f"epistemic_draws = {n} is more than the {stored} draws stored in {path}")
    t_ref_cal = None
    if RATE_AT_REFERENCE in study.epistemic_keys:
        if not params[RATE_AT_REFERENCE].get("relative", False):
            raise StudyError(study.file, KEY, study.posterior,
                             f"{RATE_AT_REFERENCE} in {path} is not a factor on the nominal "
                             "rate, which the calibration writes: not a calibration's posterior")
        t_ref_cal = _reference_temperature(idata.attrs.get("prior_study_text", ""))

    def physical(group) -> dict[str, np.ndarray]:
        if group is None:
            return {}
        out = {}
        for key in study.epistemic_keys:
            v = np.asarray(group[key].values, dtype=float).reshape(-1)
            p = params[key]
            out[key] = v * float(p["nominal"]) if p.get("relative") else v
        if RATE_AT_REFERENCE in out:
            t_ref = study.epistemic[RATE_AT_REFERENCE].reference_temperature
            if t_ref_cal is not None and t_ref is not None and t_ref != t_ref_cal:
                t_act = out.get("kinetics.activation_temperature",
                                np.full_like(out[RATE_AT_REFERENCE],
                                             study.scene.kinetics_activation_temperature))
                out[RATE_AT_REFERENCE] = out[RATE_AT_REFERENCE] * np.exp(
                    -t_act * (1.0 / t_ref - 1.0 / t_ref_cal))
        return out

    every = physical(post)
    index = thinned_indices(stored, n)
    prior_group = getattr(idata, "prior", None) if "prior" in idata.groups() else None
    return PosteriorDraws(
        calibration=str(idata.attrs.get("study_name", path.parent.name)), path=str(path),
        sha256=hashlib.sha256(data).hexdigest(), completed=str(idata.attrs.get("completed", "")),
        keys=tuple(study.epistemic_keys), draws={k: v[index] for k, v in every.items()},
        indices=index, stored=stored, posterior=every,
        prior=physical(prior_group) if prior_group is not None and all(
            k in prior_group.data_vars for k in study.epistemic_keys) else {},
        unused={name: unused_reason(name) for name in names if name not in study.epistemic_keys})


def with_posterior_sha(study, draws: PosteriorDraws):
    """The study with its SHA-256 made of its text's and its posterior file's: a run is up to
    date only with the posterior it was computed from."""
    sha = hashlib.sha256(f"{study.sha256}\n{draws.sha256}".encode()).hexdigest()
    return dataclasses.replace(study, sha256=sha)


def posterior_probability(probabilities: np.ndarray, confidence: float) -> dict:
    """The mean of P(theta_j) over posterior draws, its standard error and interval.

    Parameters
    ----------
    probabilities : numpy.ndarray
        P at each posterior draw [1] (each an estimate with its own noise, which the spread
        between draws includes).
    confidence : float
        Coverage of the interval [1].

    Returns
    -------
    dict
        ``probability`` (the mean), ``se`` (sample sd / sqrt(n)), ``cov``, ``interval``
        (mean -/+ t_{n-1} se, clipped to [0, 1]), ``n``.
    """
    p = np.asarray(probabilities, dtype=float)
    n = p.size
    mean = float(p.mean()) if n else math.nan
    se = float(p.std(ddof=1) / math.sqrt(n)) if n > 1 else math.inf
    t = float(stats.t.isf((1 - confidence) / 2, n - 1)) if n > 1 else math.inf
    low = max(0.0, mean - t * se) if math.isfinite(se) else 0.0
    high = min(1.0, mean + t * se) if math.isfinite(se) else 1.0
    return {"probability": mean, "se": se, "cov": se / mean if mean > 0 else math.inf,
            "interval": (low, high), "n": n}


def _quantiles(values) -> list[float]:
    v = np.asarray(values, dtype=float)
    return [float(q) for q in np.quantile(v, SPREAD)] if v.size else []


#: Quantiles of the spread of each input's draws, in the summary [1].
SPREAD = (0.05, 0.5, 0.95)


def _spearman(values: dict[str, np.ndarray], keys) -> list[list[float]]:
    if len(keys) < 2:
        return [[1.0]]
    rho = np.asarray(stats.spearmanr(np.column_stack([values[k] for k in keys])).statistic,
                     dtype=float)
    if rho.ndim == 0:  # two inputs: scipy gives the one coefficient
        rho = np.array([[1.0, float(rho)], [float(rho), 1.0]])
    return rho.round(4).tolist()


def prior_study_summary(study) -> dict:
    """What the study over the priors (``[hazard.posterior] prior_study``) found, from its
    ``results/<name>/summary.json``: ``probability``, ``interval``, ``band``,
    ``epistemic_probabilities`` [1] and ``status`` (``found``, or why not)."""
    if study.prior_study is None:
        return {"status": "no prior_study named in [hazard.posterior]"}
    from skidmc.ensemble.hazard_study import load_hazard_study

    base = Path(study.file).parent if Path(study.file).is_file() else Path(".")
    file = base / study.prior_study
    if not file.is_file():
        raise StudyError(study.file, "hazard.posterior.prior_study", study.prior_study,
                         f"no such hazard study file ({file})")
    prior = load_hazard_study(file)
    path = Path("results") / prior.name / "summary.json"
    out = {"file": str(file), "summary": str(path)}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {**out, "status": f"not run yet: skidmc run {file}"}
    if data.get("study", {}).get("sha256") != prior.sha256:
        return {**out, "status": f"stale (computed from another version of {file.name}): "
                                  f"skidmc run {file} --force"}
    return {**out, "status": "found", "sha256": prior.sha256,
            "probability": data["probability"],
            "interval": data["interval"], "band": data["band"],
            "epistemic_probabilities": data["epistemic_probabilities"],
            "epistemic_draws": data["epistemic_draws"]}


def posterior_summary(study, post: PosteriorDraws, result, marginals: list) -> dict:
    """The posterior's part of a hazard result (``HazardResult.posterior``): P over the
    posterior draws against P over the priors, the inputs' spread and correlation.

    `marginals` are the hazard's prior distributions of ``post.keys`` (frozen, SI)."""
    p = posterior_probability(result.epistemic_probabilities, result.confidence)
    prior_study = prior_study_summary(study)
    if prior_study.get("status") == "found":  # the prior's draws, estimated as the posterior's
        prior_study["draws_mean"] = posterior_probability(
            prior_study["epistemic_probabilities"], result.confidence)
    spread = {}
    for key, m in zip(post.keys, marginals):
        spread[key] = {"hazard_prior": [float(m.ppf(q)) for q in SPREAD],
                       "calibration_prior": _quantiles(post.prior.get(key, [])),
                       "posterior": _quantiles(post.posterior[key]),
                       "draws": _quantiles(post.draws[key])}
    return {
        "calibration": post.calibration, "file": post.path, "sha256": post.sha256,
        "completed": post.completed, "stored": post.stored, "draws": int(post.indices.size),
        "indices": post.indices.tolist(), "keys": list(post.keys),
        **p, "band": list(result.band),
        "prior": {"pooled": {"probability": result.probability,
                             "interval": list(result.interval), "cov": result.cov},
                  "study": prior_study},
        "spread": spread, "spread_quantiles": list(SPREAD),
        "correlation": {"method": "spearman", "keys": list(post.keys),
                        "posterior": _spearman(post.posterior, post.keys),
                        "draws": _spearman(post.draws, post.keys)},
        "unused": post.unused,
    }
