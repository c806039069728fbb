"""The kind ``calibration``: a study's epistemic inputs learned from the report's drops (issue 40).

A calibration study (``[study] kind = "calibration"`` and a ``[calibration]`` table,
:class:`skidmc.ensemble.study_schema.CalibrationFile`) names the study whose epistemic inputs
are the priors (``prior``) and, optionally, a study whose scenes are predicted (``predict``).
``skidmc run``:

1. trains a surrogate of ln H_c per scene on solver runs (:func:`skidmc.evaluate_batch`,
   through the ensemble's executors: local processes, or dask with ``--scheduler``);
2. samples the posterior of :mod:`skidmc.analysis.calibration` with emcee (the walkers of a
   step evaluated as one batch), and prints ArviZ's R-hat and bulk and tail ESS;
3. checks the surrogate against the solver at posterior draws, the quadrature by doubling its
   nodes, scores leave-one-target-out predictions, and predicts the ``predict`` study's H50;
4. writes ``results/<name>/posterior.nc`` (ArviZ InferenceData, netCDF through h5netcdf, with
   the study texts, version and seeds as attributes) to a temporary file renamed when complete:
   a result is whole or absent, and a rerun of the same study is up to date. The solver runs
   are kept per scene as they finish (``posterior.nc.runs.npz``, removed at the end), so
   ``--resume`` after an interruption runs none of them again; the sampling, deterministic
   given its seed, is redone (seconds to minutes) and gives the numbers of an uninterrupted
   run.

``skidmc report`` reads that file alone (no solver, no sampling) and writes the figures and
``summary.md``. Choices and sources: ``docs/calibration.md``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import time
from pathlib import Path

import numpy as np

from skidmc.scene.units import FOOT
from skidmc.workflows import reporting
from skidmc.workflows.registry import Outcome, ReportOptions, RunOptions

__all__ = ["DESCRIPTION", "REFUSED", "REPORT_OPTIONS", "RUN_OPTIONS", "CalibrationStudy",
           "default_out", "detect", "load", "report", "run"]

DESCRIPTION = ("Bayesian calibration of a study's epistemic inputs on the report's drops "
               "(surrogate, emcee, ArviZ)")
RUN_OPTIONS = frozenset({"out", "resume", "force", "workers", "scheduler"})
REPORT_OPTIONS = frozenset({"out"})
REFUSED = {
    "n": "the sampler's length is set in [calibration.sampler] (walkers, burn, steps) and the "
         "training runs in [calibration.surrogate] runs",
    "chunk_size": "its solver runs are batched per scene",
    "yes": "a calibration's size is fixed by its study (minutes, benchmarks/calibration.py)",
    "confidence": "its intervals are fixed: 90 % (5-95 %) for H50 and the go curves",
}

FT = FOOT  # [m/ft]
#: Prior draws kept (and used for the prior predictive) [1].
PRIOR_DRAWS = 2000


@dataclasses.dataclass(frozen=True)
class CalibrationStudy:
    """A validated calibration study.

    Attributes
    ----------
    name, description, text, sha256, file : str
    spec : CalibrationFile
        The file's model (:mod:`skidmc.ensemble.study_schema`).
    prior : Study
        The study whose epistemic inputs are the priors.
    predict : Study or None
    others : tuple of (str, float, float)
        Other measured finishes for the friction population: (scene, measured mu, log-sd).
    """

    name: str
    description: str
    text: str
    sha256: str
    file: str
    spec: object
    prior: object
    predict: object | None
    others: tuple = ()


def detect(doc: dict) -> bool:
    """A ``[calibration]`` table."""
    return "calibration" in doc


def load(path) -> CalibrationStudy:
    """The validated calibration study; a StudyError names the key and the value."""
    from pydantic import ValidationError

    from skidmc.analysis.calibration import _log_sd
    from skidmc.ensemble.study import load_study, parse_toml, read_study_text
    from skidmc.ensemble.study_model import StudyError
    from skidmc.ensemble.study_schema import CalibrationFile

    path = Path(path)
    text = read_study_text(path)
    doc = parse_toml(text, str(path))
    try:
        spec = CalibrationFile.model_validate(doc)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = ".".join(str(p) for p in err["loc"])
        raise StudyError(str(path), key, err.get("input"), err["msg"]) from None

    def _study(key, value):
        if value is None:
            return None
        file = (path.parent / value)
        if not file.is_file():
            raise StudyError(str(path), key, value, f"no such study file ({file})")
        return load_study(file)

    prior = _study("calibration.prior", spec.calibration.prior)
    predict = _study("calibration.predict", spec.calibration.predict)
    for sc in prior.scenes:
        if not sc.experiment:
            raise StudyError(str(path), "calibration.prior", spec.calibration.prior,
                             f"scene {sc.name!r} names no experiment: its drops are the data")
    for key in spec.calibration.quadrature:
        if all(key not in sc.factors and not (key in sc.uncertain and sc.uncertain[key].kind
                                              == "aleatory") for sc in prior.scenes):
            raise StudyError(str(path), f"calibration.quadrature.{key}",
                             spec.calibration.quadrature[key],
                             "not an aleatory input of the prior study")
    others = []
    pop = spec.calibration.friction_population
    if pop is not None and pop.other_finishes_from:
        other = _study("calibration.friction_population.other_finishes_from",
                       pop.other_finishes_from)
        unknown = set(pop.exclude) - set(other.scene_names)
        if unknown:
            raise StudyError(str(path), "calibration.friction_population.exclude",
                             sorted(unknown), f"no such scene in {pop.other_finishes_from}")
        for sc in other.scenes:
            if sc.name in pop.exclude or "mu" not in sc.uncertain:
                continue
            others.append((sc.name, sc.nominal("mu"), _log_sd(sc.uncertain["mu"])))
    return CalibrationStudy(spec.study.name, spec.study.description, text,
                            hashlib.sha256(text.encode()).hexdigest(), str(path), spec, prior,
                            predict, tuple(others))


def default_out(study: CalibrationStudy) -> Path:
    """``results/<name>/posterior.nc``."""
    return Path("results") / study.name / "posterior.nc"


def _out_path(study, out) -> Path:
    if out is None:
        return default_out(study)
    out = Path(out)
    return out if out.suffix == ".nc" else out / "posterior.nc"


def _fingerprint(study: CalibrationStudy) -> str:
    """sha256 of the calibration study's text and of the studies it names."""
    h = hashlib.sha256(study.text.encode())
    for s in (study.prior, study.predict):
        if s is not None:
            h.update(s.text.encode())
    return h.hexdigest()


# --- the run -------------------------------------------------------------------------------------


def _training_design(study, runs: int, seed: int):
    """Rows u in (0, 1)^d over the study's design columns: a Latin hypercube on normal scores
    spread evenly over [-3, 3] (the surrogate sees the prior's tails as often as its middle)."""
    from scipy import special
    from scipy.stats import qmc

    lhs = qmc.LatinHypercube(d=len(study.keys), seed=seed).random(runs)
    return special.ndtr(-3.0 + 6.0 * lhs)


def _train(study, options, seed: int, runs: int, log, counter, checkpoint: Path) -> dict:
    """Surrogate per scene of `study`, trained on `runs` solver runs each. Each scene's runs
    are kept in `checkpoint` (npz, written whole) as soon as they are done, so that
    ``--resume`` after an interruption does not run them again."""
    from skidmc.analysis.calibration import fit_surrogate
    from skidmc.ensemble.batch import evaluate_batch
    from skidmc.ensemble.sampling import transform
    from skidmc.ensemble.study_model import RATE_AT_REFERENCE

    u = _training_design(study, runs, seed)
    columns = transform(study, u)
    out = {}
    for sc, values in zip(study.scenes, columns):
        tag = f"{study.name}/{sc.name}"
        kept = _read_checkpoint(checkpoint)
        if f"{tag}|ln_h" in kept:
            ln_h = kept[f"{tag}|ln_h"]
            inputs = {k.split("|", 2)[2]: v for k, v in kept.items()
                      if k.startswith(f"{tag}|x|")}
            log(f"surrogate {tag}: {len(ln_h)} solver runs kept by the interrupted run")
        else:
            batch = {k: v for k, v in values.items() if k != RATE_AT_REFERENCE}
            t0 = time.perf_counter()
            res = evaluate_batch(batch, study.solver.as_kwargs(), base=sc.scene,
                                 workers=options.workers, scheduler=options.scheduler,
                                 solver=options.solver)
            counter["runs"] += len(res.status)
            counter["solver_seconds"] += time.perf_counter() - t0
            ok = res.status == "ok"
            if (~ok).any():
                log(f"surrogate {tag}: {int((~ok).sum())} of {len(ok)} runs censored or "
                    "failed, left out of the fit")
            inputs = {**{k: np.asarray(res.inputs[k]) for k in res.inputs},
                      **{k: v for k, v in values.items() if k == RATE_AT_REFERENCE}}
            inputs = {k: np.asarray(v, dtype=float)[ok] for k, v in inputs.items()}
            ln_h = np.log(res.critical_height[ok])
            kept.update({f"{tag}|ln_h": ln_h, **{f"{tag}|x|{k}": v for k, v in inputs.items()}})
            _write_checkpoint(checkpoint, kept)
        if len(ln_h) < 30:
            raise RuntimeError(f"scene {sc.name}: only {len(ln_h)} of {runs} training runs "
                               "ended ok (censored or failed); widen the solver's h_max")
        out[sc.name] = fit_surrogate(inputs, ln_h, seed=seed)
        s = out[sc.name]
        log(f"surrogate {tag}: {s.n_train + s.n_holdout} solver runs, ln H_c rmse "
            f"{s.rmse_train:.4f} on training, {s.rmse_holdout:.4f} held out")
    return out


def _read_checkpoint(path: Path) -> dict:
    if not path.is_file():
        return {}
    with np.load(path) as f:
        return {k: f[k] for k in f.files}


def _write_checkpoint(path: Path, kept: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **kept)
    os.replace(tmp, path)


def _drops(study) -> dict:
    from skidmc.analysis.experiments import get_experiment

    out = {}
    for sc in study.scenes:
        e = get_experiment(sc.experiment, units="m")
        if e.drops is not None:
            out[sc.name] = (e.drops.heights, e.drops.went)
    return out


def _model(cstudy: CalibrationStudy, surrogates, drops=None):
    from skidmc.analysis.calibration import FrictionPopulation, build_model

    c = cstudy.spec.calibration
    pop = None
    if c.friction_population is not None:
        p = c.friction_population
        pop = FrictionPopulation(p.median, p.median_log_sd, p.sd, p.sd_log_sd,
                                 tuple((math.log(m), s) for _n, m, s in cstudy.others), p.source)
    return build_model(cstudy.prior, surrogates, _drops(cstudy.prior) if drops is None else drops,
                       quadrature=c.quadrature, discrepancy_sd=c.discrepancy_sd,
                       misclassification=c.misclassification, population=pop)


def _sample(model, sampler, *, steps=None, burn=None, targets=None, log=None, seed=None,
            initial=None):
    from skidmc.analysis.calibration import run_emcee

    def progress(done, total):
        if log is not None:
            log(f"  emcee: {done} of {total} steps")

    return run_emcee(lambda z: model.log_posterior(z, targets=targets), model.ndim,
                     walkers=sampler.walkers, burn=sampler.burn if burn is None else burn,
                     steps=steps or sampler.steps, thin=sampler.thin,
                     seed=sampler.seed if seed is None else seed, progress=progress,
                     initial=initial)


def _posterior_dataset(model, chain):
    import xarray as xr

    values = model.values(chain).astype(np.float32)  # 7 digits: ample for draws, half the file
    return xr.Dataset({p.name: (("chain", "draw"), values[..., i])
                       for i, p in enumerate(model.parameters)},
                      coords={"chain": np.arange(chain.shape[0]),
                              "draw": np.arange(chain.shape[1])})


def _check_surrogate(cstudy, model, z, options, counter, rng) -> dict:
    """ln H_c of the solver against the surrogate at posterior draws `z` (one aleatory draw
    each): rmse and largest error per scene."""
    from scipy import special

    from skidmc.ensemble.batch import evaluate_batch
    from skidmc.ensemble.study_model import RATE_AT_REFERENCE, prefactor_from_rate

    out = {}
    for sc, t in zip(cstudy.prior.scenes, model.targets):
        inputs = {k: np.full(len(z), v, dtype=float) for k, v in t.nominal.items()}
        for i, p in enumerate(model.parameters):
            if p.key in inputs and p.applies(t.name):
                v = p.value(z[:, i])
                inputs[p.key] = inputs[p.key] * v if p.relative else v
        for key in list(inputs):  # every aleatory input drawn at random
            dist = sc.factors.get(key) or (sc.uncertain.get(key) if key in sc.uncertain and
                                           sc.uncertain[key].kind == "aleatory" else None)
            if dist is None:
                continue
            a = dist.frozen.ppf(np.clip(special.ndtr(rng.standard_normal(len(z))), 1e-9,
                                        1 - 1e-9))
            base = sc.nominal(key) if key in sc.factors or dist.relative else None
            if key in sc.factors:
                inputs[key] = inputs[key] * a
            elif dist.relative:
                inputs[key] = base * a
            else:
                inputs[key] = a
        batch = {k: v for k, v in inputs.items() if k != RATE_AT_REFERENCE}
        if RATE_AT_REFERENCE in inputs:
            t_ref = sc.uncertain[RATE_AT_REFERENCE].reference_temperature
            batch["kinetics.prefactor"] = prefactor_from_rate(
                inputs[RATE_AT_REFERENCE], inputs.get(
                    "kinetics.activation_temperature",
                    sc.nominal("kinetics.activation_temperature")), t_ref)
        t0 = time.perf_counter()
        res = evaluate_batch(batch, cstudy.prior.solver.as_kwargs(), base=sc.scene,
                             workers=options.workers, scheduler=options.scheduler,
                             solver=options.solver)
        counter["runs"] += len(z)
        counter["solver_seconds"] += time.perf_counter() - t0
        ok = res.status == "ok"
        err = np.log(res.critical_height[ok]) - t.surrogate({k: v[ok] for k, v in inputs.items()})
        out[t.name] = {"draws": int(ok.sum()), "rmse": float(np.sqrt(np.mean(err**2))),
                       "max_abs": float(np.abs(err).max()),
                       "holdout_rmse": t.surrogate.rmse_holdout}
    return out


def _curves(model, z, heights_ft):
    """P(go | H) quantiles (5, 50, 95 %) and mean over draws `z` per target on `heights_ft`."""
    ln_h = np.log(np.asarray(heights_ft) * FT)
    out = []
    for t in model.targets:
        p = np.concatenate([model.go_probability(z[i:i + 500], t, ln_h)
                            for i in range(0, len(z), 500)])
        out.append(np.stack([np.quantile(p, 0.05, axis=0), np.quantile(p, 0.5, axis=0),
                             np.quantile(p, 0.95, axis=0), p.mean(axis=0)]))
    return np.stack(out)


def _h50_ft(model, z, target):
    return np.exp(np.concatenate([model.ln_h50(z[i:i + 500], target)
                                  for i in range(0, len(z), 500)])) / FT


def _cross_validation(cstudy, model, prior_z, posterior_z, log):
    """Leave one target out: calibrate on the others, predict its drops. Each run starts its
    walkers at draws of the full posterior and burns in for half the main run's burn-in."""
    from skidmc.analysis.calibration import brier_score, log_score

    c = cstudy.spec.calibration.sampler
    rows = []
    for t in model.targets:
        if t.ln_heights.size == 0:
            continue
        others = [o.name for o in model.targets if o.name != t.name]
        log(f"cross-validation: {t.name} left out")
        rng = np.random.default_rng(c.seed + 1 + len(rows))
        start = posterior_z[rng.choice(len(posterior_z), c.walkers, replace=False)]
        chain, _lnp, _acc = _sample(model, c, steps=c.cv_steps, burn=c.burn // 2,
                                    targets=others, log=None, seed=c.seed + 1 + len(rows),
                                    initial=start)
        z = chain.reshape(-1, model.ndim)
        post = model.go_probability(z, t, t.ln_heights, observed=True).mean(axis=0)
        prior = model.go_probability(prior_z, t, t.ln_heights, observed=True).mean(axis=0)
        train = np.concatenate([o.went for o in model.targets if o.name != t.name])
        base = np.full(t.went.shape, train.mean())
        coin = np.full(t.went.shape, 0.5)
        row = {"target": t.name, "drops": int(t.went.size), "goes": int(t.went.sum())}
        for name, p in (("posterior", post), ("prior", prior), ("base_rate", base),
                        ("coin", coin)):
            row[f"log_{name}"] = log_score(p, t.went)
            row[f"brier_{name}"] = brier_score(p, t.went)
        row["h50_ft"] = [float(q) for q in np.quantile(_h50_ft(model, z[::4], t),
                                                        [0.05, 0.5, 0.95])]
        rows.append(row)
    return rows


def _predict(cstudy, model, z, surrogates, rng):
    """H50 of the `predict` study's scenes from the posterior draws `z`: shared parameters
    from the posterior, each finish's friction from its measurement and the population, a new
    discrepancy drawn from its prior (an unseen target)."""
    from skidmc.analysis.calibration import (
        CalibrationModel,
        Parameter,
        _log_sd,
        _same,
        finish_friction_draws,
        target_from_scene,
    )
    from skidmc.analysis.experiments import get_experiment

    c = cstudy.spec.calibration
    rows = []
    for sc in cstudy.predict.scenes:
        t = target_from_scene(sc, surrogates[sc.name], c.quadrature, experiment=sc.experiment)
        # physical parameter values for this scene, as factors/values of its keys
        params, cols = [], []
        for key, dist in sc.uncertain.items():
            if dist.kind != "epistemic":
                continue
            if key == "mu":
                mu = finish_friction_draws(model, z, sc.nominal("mu"), _log_sd(dist), rng)
                params.append(Parameter("mu", None, "mu", (sc.name,), True))
                cols.append(mu / sc.nominal("mu"))
                continue
            match = [i for i, p in enumerate(model.parameters) if p.key == key and any(
                _same(dist, s.uncertain[key]) for s in cstudy.prior.scenes
                if key in s.uncertain and p.applies(s.name))]
            if match:
                i = match[0]
                params.append(dataclasses.replace(model.parameters[i], prior=None,
                                                  targets=(sc.name,)))
                cols.append(model.parameters[i].value(z[:, i]))
            else:  # a key the first series did not learn: its own prior
                params.append(Parameter(key, None, key, (sc.name,), dist.relative))
                cols.append(dist.frozen.ppf(np.clip(rng.random(len(z)), 1e-9, 1 - 1e-9)))
        sd = math.hypot(c.discrepancy_sd, surrogates[sc.name].rmse_holdout)
        params.append(Parameter(f"discrepancy[{sc.name}]", None, None, (sc.name,)))
        cols.append(sd * rng.standard_normal(len(z)))
        m = CalibrationModel(tuple(params), (t,))
        h50 = np.exp(m.ln_h50(np.stack(cols, axis=1), t)) / FT
        e = get_experiment(sc.experiment)
        q = np.quantile(h50, [0.05, 0.5, 0.95])
        rows.append({"scene": sc.name, "experiment": sc.experiment,
                     "mu_measured": sc.nominal("mu"), "h50_ft": [float(v) for v in q],
                     "experimental_h50_ft": e.h50,
                     "inside_90": bool(q[0] <= e.h50 <= q[2])})
    return rows


def run(study: CalibrationStudy, options: RunOptions) -> Outcome:
    """``skidmc run`` of a calibration study (module docstring)."""
    import arviz as az
    import xarray as xr

    from skidmc import __version__
    from skidmc.analysis.calibration import diagnostic_lines, diagnostics, quadrature_error
    from skidmc.ensemble.storage import timestamp

    log = (lambda line: None) if options.quiet else options.log
    path = _out_path(study, options.out)
    fingerprint = _fingerprint(study)
    if path.is_file() and not options.force:
        attrs = xr.open_dataset(path, engine="h5netcdf").attrs
        if attrs.get("fingerprint") == fingerprint:
            return Outcome(0, path, (f"{path}: up to date (a complete calibration of this "
                                     f"study, completed {attrs.get('completed', '?')}); nothing "
                                     "computed (--force recomputes it)",))
        return Outcome(2, None, (f"skidmc run: error: {path} holds another calibration (its "
                                 "study or the studies it names changed); --force replaces it",))
    c = study.spec.calibration
    checkpoint = path.with_name(path.name + ".runs.npz")
    if checkpoint.is_file() and not options.resume:
        if not options.force:
            return Outcome(2, None, (f"skidmc run: error: {checkpoint} holds the solver runs of "
                                     "an interrupted calibration: --resume uses them, --force "
                                     "discards them",))
        checkpoint.unlink()
    started = time.perf_counter()
    counter = {"runs": 0, "solver_seconds": 0.0}
    surrogates = _train(study.prior, options, c.surrogate.seed, c.surrogate.runs, log, counter,
                        checkpoint)
    if study.predict is not None:
        surrogates_pred = _train(study.predict, options, c.surrogate.seed + 1,
                                 c.surrogate.runs, log, counter, checkpoint)
    model = _model(study, surrogates)
    log(f"sampling {model.ndim} parameters: {c.sampler.walkers} walkers x "
        f"{c.sampler.burn} + {c.sampler.steps} steps (emcee)")
    t0 = time.perf_counter()
    chain, lnp, acceptance = _sample(model, c.sampler, log=log)
    sample_seconds = time.perf_counter() - t0
    posterior = _posterior_dataset(model, chain)
    diag = diagnostics(posterior)
    z = chain.reshape(-1, model.ndim)
    rng = np.random.default_rng(c.sampler.seed)
    prior_z = rng.standard_normal((PRIOR_DRAWS, model.ndim))
    pick = z[rng.choice(len(z), size=min(200, len(z)), replace=False)]
    quad = quadrature_error(model, pick)
    check = {}
    if c.surrogate.check_draws:
        check = _check_surrogate(study, model, z[rng.choice(len(z), c.surrogate.check_draws,
                                                            replace=False)],
                                 options, counter, rng)
    heights_ft = np.geomspace(0.3, 3000, 121)
    curves = _curves(model, z[::2], heights_ft)
    curves_prior = _curves(model, prior_z, heights_ft)
    h50_post = {t.name: _h50_ft(model, z, t).reshape(chain.shape[:2]) for t in model.targets}
    h50_prior = {t.name: _h50_ft(model, prior_z, t) for t in model.targets}
    cv = _cross_validation(study, model, prior_z, z, log) if c.sampler.cv_steps else []
    predictions = (_predict(study, model, z[::2], surrogates_pred, rng)
                   if study.predict is not None else [])
    minutes = (time.perf_counter() - started) / 60

    prior_values = model.values(prior_z)
    prior_ds = xr.Dataset({p.name: (("chain", "draw"), prior_values[None, :, i].astype(
        np.float32))
                           for i, p in enumerate(model.parameters)})
    h50_ds = xr.Dataset({f"h50[{k}]": (("chain", "draw"), v.astype(np.float32))
                         for k, v in h50_post.items()})
    for v in h50_ds.data_vars.values():
        v.attrs["units"] = "ft"
    sample_stats = xr.Dataset({"lp": (("chain", "draw"), lnp)})
    obs = {}
    for t in model.targets:
        obs[f"height[{t.name}]"] = xr.DataArray(np.exp(t.ln_heights) / FT,
                                                dims=(f"drop_{t.name}",),
                                                attrs={"units": "ft"})
        obs[f"went[{t.name}]"] = xr.DataArray(t.went.astype(np.int8), dims=(f"drop_{t.name}",))
    idata = az.InferenceData(posterior=posterior, prior=prior_ds,
                             posterior_predictive=h50_ds, sample_stats=sample_stats,
                             observed_data=xr.Dataset(obs))
    summary = {
        "diagnostics": diag, "acceptance": acceptance,
        "quadrature_error": quad, "surrogate_check": check,
        "surrogates": {k: {"keys": list(s.keys), "rmse_train": s.rmse_train,
                           "rmse_holdout": s.rmse_holdout, "n_train": s.n_train,
                           "n_holdout": s.n_holdout} for k, s in surrogates.items()},
        "folded_sd": {t.name: t.folded_sd for t in model.targets},
        "parameters": [{"name": p.name, "key": p.key, "relative": p.relative, "unit": p.unit,
                        "source": p.source,
                        "nominal": (model.targets[[t.name for t in model.targets].index(
                            p.targets[0])].nominal.get(p.key) if p.targets and p.key else None)}
                       for p in model.parameters],
        "prior_h50_ft": {k: [float(q) for q in np.quantile(v, [0.05, 0.5, 0.95])]
                         for k, v in h50_prior.items()},
        "cross_validation": cv, "predictions": predictions,
        "experiments": {t.name: t.experiment for t in model.targets},
        "cost": {"solver_runs": counter["runs"], "solver_minutes": counter["solver_seconds"] / 60,
                 "sampling_minutes": sample_seconds / 60, "minutes": minutes,
                 "log_posterior_evaluations": c.sampler.walkers * (c.sampler.burn
                                                                   + c.sampler.steps)},
    }
    idata.attrs.update({
        "title": f"skidmc calibration: {study.name}", "skidmc_version": __version__,
        "study_name": study.name, "study_file": study.file, "study_text": study.text,
        "study_sha256": study.sha256, "prior_study_text": study.prior.text,
        "predict_study_text": study.predict.text if study.predict is not None else "",
        "fingerprint": fingerprint, "sampler_seed": c.sampler.seed,
        "surrogate_seed": c.surrogate.seed, "command": options.command or "",
        "completed": timestamp(), "summary": reporting.dumps(summary, indent=None),
    })
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    idata.to_netcdf(str(tmp), engine="h5netcdf")
    curve_ds = xr.Dataset(
        {"posterior": (("target", "quantity", "height"), curves),
         "prior": (("target", "quantity", "height"), curves_prior)},
        coords={"target": [t.name for t in model.targets],
                "quantity": ["q05", "q50", "q95", "mean"], "height": heights_ft})
    curve_ds["height"].attrs["units"] = "ft"
    curve_ds.to_netcdf(tmp, mode="a", group="go_curves", engine="h5netcdf")
    os.replace(tmp, path)
    checkpoint.unlink(missing_ok=True)
    lines = [f"{path}: {model.ndim} parameters, {chain.shape[0]} walkers x {chain.shape[1]} "
             f"kept draws; {counter['runs']} solver runs, {minutes:.1f} min"]
    lines += diagnostic_lines(diag)
    return Outcome(0, path, tuple(lines))


# --- the report ----------------------------------------------------------------------------------


def report(target, options: ReportOptions) -> Outcome:
    """``skidmc report`` of a calibration (its study, or its posterior.nc)."""
    from skidmc.workflows.calibration_report import write_calibration_report

    path = target if isinstance(target, Path) else default_out(target)
    if not path.is_file():
        return Outcome(2, None, (f"skidmc report: error: {options.source}: no result yet at "
                                 f"{path}; run it first: skidmc run {options.source}",))
    out = Path(options.out) if options.out else path.parent
    summary = write_calibration_report(path, out)
    return Outcome(0, out / "summary.md", (), tuple(summary))
