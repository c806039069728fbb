"""Does the calibration's sampler keep the posterior's spread? (issue 40 E, the SBC's p = 0.012)

    python scripts/calibration_sampler_check.py [--seeds 40] [--replications 24]
        [--out results/validation]

writes ``calibration_sampler_check.md``. Two checks where the exact answer is known, each with
the calibration's moves (differential evolution 80 %, snooker 20 %) as
:func:`skidmc.analysis.calibration.run_emcee` runs them (the corrected snooker move) and with
emcee 3.1.6's own ``DESnookerMove`` in its place, at the SBC's settings (36 walkers, 300 + 600
steps, walkers started at N(0, 1) draws):

1. a 15-dimensional correlated Gaussian (covariance 0.3 (A A^T / 15 + I), A standard normal,
   seed 0): the draws' sd against the exact one, per coordinate and seed;
2. a 2-parameter version of the SBC's model (``scripts/calibration_validation.py``): the
   activation temperature and the quartz discrepancy free (the pair whose ranks were most
   correlated in the SBC), every other score held at its true value, drops simulated at a
   prior draw; the exact posterior on a 101 x 101 grid over [-5, 5]^2 (spacing 0.1: Sheppard's
   correction to a variance of ~0.3 is 0.0008) against emcee's draws.

The ratio reported is exp(mean ln(sd_emcee / sd_exact)) with the standard error of that mean.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))


def _sample(log_prob, ndim: int, seed: int, snooker: str) -> np.ndarray:
    """Kept draws (walkers x steps, ndim) at the SBC's settings."""
    import emcee

    from skidmc.analysis.calibration import run_emcee

    if snooker == "corrected":
        chain, _, _ = run_emcee(log_prob, ndim, walkers=36, burn=300, steps=600, thin=1,
                                seed=seed)
        return chain.reshape(-1, ndim)
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(36, ndim, log_prob, vectorize=True, moves=moves)
    sampler._random = np.random.mtrand.RandomState(seed)
    sampler.run_mcmc(np.random.default_rng(seed).standard_normal((36, ndim)), 900,
                     progress=False)
    return sampler.get_chain(discard=300).reshape(-1, ndim)


def _ratio(logs) -> tuple[float, float, int]:
    v = np.asarray(logs, dtype=float).ravel()
    return math.exp(v.mean()), v.std(ddof=1) / math.sqrt(v.size), v.size


def gaussian_log_ratios(seeds, snooker: str) -> np.ndarray:
    """ln(sd of the draws / exact sd), (seed, coordinate), for a 15-dimensional correlated
    Gaussian (a fixed covariance) sampled at the SBC's settings with each seed of `seeds`
    (also tests/test_calibration.py's check of the sampler's spread)."""
    ndim = 15
    a = np.random.default_rng(0).standard_normal((ndim, ndim))
    cov = 0.3 * (a @ a.T / ndim + np.eye(ndim))
    prec = np.linalg.inv(cov)

    def log_prob(x):
        return -0.5 * np.einsum("ij,jk,ik->i", x, prec, x)

    return np.array([np.log(_sample(log_prob, ndim, s, snooker).std(axis=0)
                            / np.sqrt(np.diag(cov))) for s in seeds])


def gaussian(seeds: int, snooker: str) -> tuple[float, float, int]:
    return _ratio(gaussian_log_ratios(range(seeds), snooker))


def grid(replications: int, seed: int = 8) -> dict[str, tuple[float, float, int]]:
    from calibration_validation import sbc_model

    from skidmc.analysis.calibration import simulate_drops

    model = sbc_model(8)
    names = [p.name for p in model.parameters]
    free = [names.index("kinetics.activation_temperature"), names.index("discrepancy[quartz]")]
    rng = np.random.default_rng(seed)
    g = np.linspace(-5, 5, 101)
    g1, g2 = (x.ravel() for x in np.meshgrid(g, g, indexing="ij"))
    logs: dict[str, list] = {"corrected": [], "emcee 3.1.6": []}
    for _ in range(replications):
        z_true = rng.standard_normal(model.ndim)
        sim = simulate_drops(model, z_true, rng)

        def log_prob(z2, sim=sim, z_true=z_true):
            z = np.repeat(z_true[None, :], len(z2), axis=0)
            z[:, free] = z2
            return sim.log_posterior(z)

        lp = np.concatenate([log_prob(np.column_stack([g1[i:i + 2000], g2[i:i + 2000]]))
                             for i in range(0, g1.size, 2000)]).reshape(g.size, g.size)
        w = np.exp(lp - lp.max())
        w /= w.sum()
        exact = []
        for k in range(2):
            marginal = w.sum(axis=1 - k)
            mean = (marginal * g).sum()
            exact.append(math.sqrt((marginal * (g - mean) ** 2).sum()))
        seed_k = int(rng.integers(2**31))
        for snooker in logs:
            logs[snooker].append(np.log(_sample(log_prob, 2, seed_k, snooker).std(axis=0)
                                        / np.array(exact)))
    return {k: _ratio(v) for k, v in logs.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--replications", type=int, default=24)
    ap.add_argument("--out", default=str(ROOT / "results" / "validation"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = [("15-dimensional Gaussian", f"{args.seeds} seeds", s, gaussian(args.seeds, s))
            for s in ("corrected", "emcee 3.1.6")]
    rows += [("2-parameter SBC model against its grid posterior",
              f"{args.replications} replications", s, r)
             for s, r in grid(args.replications).items()]
    minutes = (time.perf_counter() - t0) / 60
    lines = ["# Calibration: does the sampler keep the posterior's spread?", "",
             f"Written by `python scripts/calibration_sampler_check.py --seeds {args.seeds} "
             f"--replications {args.replications}` ({minutes:.1f} min on two shared cores); "
             "what each check is: the script's docstring. emcee, 36 walkers, 300 + 600 steps, "
             "moves: differential evolution 80 % and snooker 20 %, the snooker move either "
             "the calibration's (corrected as in emcee's pull request #531) or emcee 3.1.6's "
             "own.", "",
             "| target | size | snooker move | sd of the draws / exact sd | standard error "
             "of its log | values |", "|---|---|---|---|---|---|"]
    for target, size, snooker, (ratio, se, n) in rows:
        lines.append(f"| {target} | {size} | {snooker} | {ratio:.3f} | {se:.4f} | {n} |")
    lines += ["", "A ratio below 1 by many standard errors is a posterior too narrow: the "
              "truths of a simulation-based calibration then fall in the outer rank bins too "
              "often (results/validation/calibration_sbc.md)."]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "calibration_sampler_check.md").write_text("\n".join(lines) + "\n")
    print(out / "calibration_sampler_check.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
