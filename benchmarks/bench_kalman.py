"""Per-step cost of the exact LPV Kalman filter, side by side with filterpy.

Not a test: timings are noisy on a shared machine, so every figure printed is
measured in the same run, interleaved (best of ``--repeat`` rounds), and the
ratios are what to read.

The problem: a random affine LPV model (one scheduling variable, scheduling-
dependent A, C, G, H; ``S = 0`` so that filterpy's KalmanFilter, which has no
cross-covariance, solves the same problem), ``p_t = sin(0.25 t)``, data
simulated from the model. Rows:

- ``lpvest step``: ``LPVKalmanFilter.step(dict)``, validation, evaluation of
  the p-dependent matrices, Joseph forms, log-likelihood, output dict;
- ``lpvest run_streaming``: the same through :func:`run_streaming` (the
  streaming loop: it also slices the inputs and stacks the outputs);
- ``lpvest batch (auto)``, ``(scan)``, ``(sequential)``: :func:`kalman_filter`
  over the whole trajectory with ``method="auto"`` (what users get),
  ``"scan"`` (the parallel-in-time blocked scan) and ``"sequential"`` (the
  covariance recursion sample by sample);
- ``lpvest kalman_step (matrices given)``: the pure step function on
  matrices evaluated beforehand for the whole trajectory, no validation: the
  like-for-like comparison with the next row;
- ``filterpy (matrices given)``: ``predict(); update(z)`` with F, H, Q, R
  precomputed for every step (filterpy never evaluates the LPV model);
- ``filterpy + model.at(p)``: the same, evaluating the model at ``p_t`` each
  step as a streaming filterpy user would.

The benchmark also checks that lpvest and filterpy agree on the estimates,
and that the scan agrees with the sequential recursion.

Side by side with ``lpvest step``, the row ``native FMU doStep (C host)``: the
same model as a native Kalman FMU (``lpvest build --backend native``; built
into ``--native-fmus DIR``, default ``fmu-build-native/bench-kalman``) stepped
in a bare C host (``benchmarks/native_step.c``: no Python in that process;
the issue's target is <= 2 us for n_x <= 4), and ``native FMU set+step+get``
with the inputs set and every output read each sample.

Two further tables: the per-call time of ``method="scan"`` and
``"sequential"`` against the number of samples ``T`` (where ``"auto"``
should switch: :data:`~lpvest.estimators.kalman.SCAN_MIN_SAMPLES`), and
against larger ``n_x``.

Run::

    .venv/bin/python benchmarks/bench_kalman.py [--steps 2000] [--repeat 8] [--native-fmus DIR]
"""

from __future__ import annotations

import os

# Small matrices: OpenBLAS's worker threads only add synchronisation cost, and
# on a loaded machine they dominate (n_x = 10 ran 3x slower with the default).
# Both libraries run under the same setting; override from the environment.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from lpvest import AffineLPV, Monomial, SchedulingSpace  # noqa: E402
from lpvest.core._protocol import run_streaming  # noqa: E402
from lpvest.estimators.kalman import (  # noqa: E402
    KalmanModel,
    KalmanState,
    LPVKalmanFilter,
    kalman_filter,
    kalman_step,
)


def random_model(nx: int, ny: int, nu: int, rng: np.random.Generator, *, cross: bool = False) -> AffineLPV:
    """The benchmark problem; ``cross=True`` adds a cross-covariance
    ``S != 0`` (then filterpy, which has none, does not apply)."""
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    basis = [Monomial.component(0, space)]
    A0 = rng.standard_normal((nx, nx))
    A0 *= 0.8 / max(abs(np.linalg.eigvals(A0)))
    qa = rng.standard_normal((nx, nx))
    qq = rng.standard_normal((nx, nx))
    qr = rng.standard_normal((ny, ny))
    Q = 0.1 * (qq @ qq.T + nx * np.eye(nx))
    R = 0.1 * (qr @ qr.T + ny * np.eye(ny))
    S = np.zeros((nx, ny))
    if cross:  # S = 0.5 Q^(1/2) E R^(1/2)^T with orthonormal E: Sigma stays positive definite
        E = np.linalg.qr(rng.standard_normal((nx, max(nx, ny))))[0][:, :ny] if nx >= ny else np.eye(nx, ny)
        S = 0.5 * np.linalg.cholesky(Q) @ E @ np.linalg.cholesky(R).T
    return AffineLPV.from_matrices(
        space,
        basis,
        A={"1": A0, "p": 0.1 * rng.standard_normal((nx, nx))},
        B=rng.standard_normal((nx, nu)),
        C={"1": rng.standard_normal((ny, nx)), "p": 0.2 * rng.standard_normal((ny, nx))},
        G={"1": np.eye(nx), "p": 0.1 * qa},
        H={"1": np.eye(ny), "p": 0.2 * np.eye(ny)},
        Q=Q,
        R=R,
        S=S,
        P0=np.eye(nx),
    )


def _best(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench(nx: int, ny: int, steps: int, repeat: int, seed: int) -> dict[str, float]:
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(seed)
    nu = 1
    model = random_model(nx, ny, nu, rng)
    k = np.arange(steps)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=rng).y
    mats = model.at_batch(p)
    Q, R = model.noise.Q, model.noise.R
    Fs, Bs, Hs = mats.A, mats.B, mats.C
    Qs = mats.G @ Q @ np.swapaxes(mats.G, 1, 2)
    Rs = mats.H @ R @ np.swapaxes(mats.H, 1, 2)

    kf = LPVKalmanFilter(model)
    rows = [{"p": p[t], "u": u[t], "y": y[t]} for t in range(steps)]

    def lp_step() -> None:
        kf.reset()
        step = kf.step
        for r in rows:
            step(r)

    def lp_stream() -> None:
        kf.reset()
        run_streaming(kf, {"p": p, "u": u, "y": y})

    def lp_auto() -> None:
        kalman_filter(model, p, u, y)

    def lp_scan() -> None:
        kalman_filter(model, p, u, y, method="scan")

    def lp_seq() -> None:
        kalman_filter(model, p, u, y, method="sequential")

    scan, seq = (kalman_filter(model, p, u, y, method=mt) for mt in ("scan", "sequential"))
    for a, b in zip(scan, seq, strict=True):
        scale = np.max(np.abs(b))
        assert np.max(np.abs(np.asarray(a) - b)) <= 1e-9 * scale, "scan and sequential disagree"

    km = KalmanModel(model)
    sms = km.step_matrices_batch(p)
    given = [(sms.at(t), u[t], y[t]) for t in range(steps)]

    def lp_given() -> None:
        state = KalmanState(model.x0, model.P0, 0)
        for sm, ut, yt in given:
            state = kalman_step(state, sm, ut, yt).next

    fp = KalmanFilter(dim_x=nx, dim_z=ny, dim_u=nu)
    zs = [y[t].reshape(ny, 1) for t in range(steps)]
    us = [u[t].reshape(nu, 1) for t in range(steps)]

    def fp_reset() -> None:
        fp.x = model.x0.reshape(nx, 1).copy()
        fp.P = model.P0.copy()

    # filterpy's update-then-predict order: at step t, update with y_t at p_t
    # (H_t, R_t), then predict with F_t, B_t, Q_t.
    def fp_given() -> None:
        fp_reset()
        for t in range(steps):
            fp.H = Hs[t]
            fp.R = Rs[t]
            fp.update(zs[t])
            fp.F = Fs[t]
            fp.B = Bs[t]
            fp.Q = Qs[t]
            fp.predict(u=us[t])

    def fp_eval() -> None:
        fp_reset()
        for t in range(steps):
            m = model.at(p[t])
            fp.H = m.C
            fp.R = m.H @ R @ m.H.T
            fp.update(zs[t])
            fp.F = m.A
            fp.B = m.B
            fp.Q = m.G @ Q @ m.G.T
            fp.predict(u=us[t])

    # the two agree (same problem): filtered state of the last step
    fp_given()
    fp.x = model.x0.reshape(nx, 1).copy()
    fp.P = model.P0.copy()
    ours = kalman_filter(model, p, u, y)
    fp_reset()
    for t in range(steps):
        fp.H, fp.R = Hs[t], Rs[t]
        fp.update(zs[t])
        if t in (0, steps // 2, steps - 1):
            err = np.max(np.abs(fp.x[:, 0] - ours.filtered_means[t]))
            assert err < 1e-8 * (1 + np.max(np.abs(ours.filtered_means[t]))), (t, err)
        fp.F, fp.B, fp.Q = Fs[t], Bs[t], Qs[t]
        fp.predict(u=us[t])

    fns = {
        "lpvest step": lp_step,
        "lpvest run_streaming": lp_stream,
        "lpvest batch (auto)": lp_auto,
        "lpvest batch (scan)": lp_scan,
        "lpvest batch (sequential)": lp_seq,
        "lpvest kalman_step (given)": lp_given,
        "filterpy (matrices given)": fp_given,
        "filterpy + model.at(p)": fp_eval,
    }
    best = dict.fromkeys(fns, np.inf)
    names = list(fns)
    for r in range(repeat):  # interleaved rounds: load changes hit every row alike
        # rotate the order each round: the row run right after a long streaming
        # loop starts with cold caches, and no row should always be that one
        for name in names[r % len(names) :] + names[: r % len(names)]:
            best[name] = min(best[name], _best(fns[name], 1))
    return {name: 1e6 * t / steps for name, t in best.items()}


def native_kalman(nx: int, ny: int, seed: int, folder: Path, steps: int, repeat: int) -> dict[str, float]:
    """Microseconds per sample of the native Kalman FMU of :func:`bench`'s model
    (the same draws) in the bare C host."""
    from lpvest import SystemFile, save_system

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from native_bench import build_native, step_times

    model = random_model(nx, ny, 1, np.random.default_rng(seed))
    name = f"bench-kalman-nx{nx}-ny{ny}-seed{seed}"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.toml"
        save_system(SystemFile(name=name, title=f"bench_kalman's random model, n_x = {nx}, n_y = {ny}",
                               models={"plant": model}, default="plant", scheduling=model.space), path)
        (fmu,) = build_native([path], folder, roles=["Kalman"]).values()
    full, step = step_times(fmu, steps=max(20 * steps, 10_000), repeat=repeat)
    return {"native FMU doStep (C host)": step / 1e3, "native FMU set+step+get": full / 1e3}


def bench_cross(nx: int, ny: int, steps: int, repeat: int, seed: int) -> dict[str, float]:
    """Microseconds per step with a cross-covariance S != 0 (the decorrelation
    has work to do): the streaming step loop against the batch methods."""
    rng = np.random.default_rng(seed)
    model = random_model(nx, ny, 1, rng, cross=True)
    k = np.arange(steps)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=rng).y
    kf = LPVKalmanFilter(model)
    rows = [{"p": p[t], "u": u[t], "y": y[t]} for t in range(steps)]

    def lp_step() -> None:
        kf.reset()
        for r in rows:
            kf.step(r)

    fns = {"step": lp_step}
    for mt in ("auto", "scan", "sequential"):
        fns[mt] = lambda mt=mt: kalman_filter(model, p, u, y, method=mt)
    scan, seq = (kalman_filter(model, p, u, y, method=mt) for mt in ("scan", "sequential"))
    for a, b in zip(scan, seq, strict=True):
        assert np.max(np.abs(np.asarray(a) - b)) <= 1e-9 * np.max(np.abs(b)), "scan and sequential disagree"
    best = dict.fromkeys(fns, np.inf)
    names = list(fns)
    for r in range(repeat):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            best[name] = min(best[name], _best(fns[name], 1))
    return {name: 1e6 * t / steps for name, t in best.items()}


def bench_methods(nx: int, ny: int, lengths: list[int], repeat: int, seed: int) -> dict[int, dict[str, float]]:
    """Seconds per call of kalman_filter(method=...) for trajectories of each length."""
    rng = np.random.default_rng(seed)
    model = random_model(nx, ny, 1, rng)
    km = KalmanModel(model)
    out = {}
    for T in lengths:
        k = np.arange(T)
        p = np.sin(0.25 * k)[:, None]
        u = np.sin(0.1 * k)[:, None]
        y = model.simulate(p, u, rng=rng).y
        best = {"sequential": np.inf, "scan": np.inf}
        reps = max(repeat, 2000 // max(T, 1))  # short runs: more rounds
        for _ in range(reps):
            for mt in best:
                run = lambda mt=mt, p=p, u=u, y=y: kalman_filter(km, p, u, y, method=mt)  # noqa: E731
                best[mt] = min(best[mt], _best(run, 1))
        out[T] = best
    return out


def bench_truncated(nx: int, ny: int, taus: list[int], steps: int, repeat: int, seed: int) -> dict[int, float]:
    """Per-step cost of TruncatedKalmanFilter.step against tau (O(tau) expected),
    timed after the window has filled."""
    from lpvest.estimators._truncated import TruncatedKalmanFilter

    rng = np.random.default_rng(seed)
    model = random_model(nx, ny, 1, rng)
    warm = max(taus) + 1
    k = np.arange(warm + steps)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=rng).y
    rows = [{"p": p[t], "u": u[t], "y": y[t]} for t in range(warm + steps)]
    filters, states = {}, {}
    for tau in taus:
        tf = TruncatedKalmanFilter(model, tau, start=np.zeros((nx, nx)))
        for r in rows[:warm]:
            tf.step(r)
        filters[tau], states[tau] = tf, tf.get_state()
    best = dict.fromkeys(taus, np.inf)
    for _ in range(repeat):
        for tau, tf in filters.items():
            def run(tf=tf, st=states[tau]) -> None:
                tf.set_state(st)
                for r in rows[warm:]:
                    tf.step(r)
            best[tau] = min(best[tau], _best(run, 1))
    return {tau: 1e6 * t / steps for tau, t in best.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ny", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--crossover", type=int, nargs="+", default=[16, 32, 48, 64, 96, 128, 256],
                        help="trajectory lengths for the scan/sequential crossover table")
    parser.add_argument("--large", type=int, nargs="+", default=[20, 40],
                        help="larger n_x for the scan/sequential comparison")
    parser.add_argument("--taus", type=int, nargs="+", default=[1, 10, 50],
                        help="memories for the truncated-filter rows (n_x = 4, n_y = 1)")
    parser.add_argument("--native-fmus", default="fmu-build-native/bench-kalman",
                        help="folder of the native Kalman FMUs of the benchmark's models")
    args = parser.parse_args()
    print(f"microseconds per step, best of {args.repeat} interleaved rounds, {args.steps} steps")
    for ny in args.ny:
        print(f"\nn_y = {ny}, n_u = 1")
        header = f"{'':28}" + "".join(f"{'n_x = ' + str(n):>12}" for n in (2, 4, 10))
        print(header)
        res = {nx: bench(nx, ny, args.steps, args.repeat, args.seed)
               | native_kalman(nx, ny, args.seed, Path(args.native_fmus), args.steps, args.repeat)
               for nx in (2, 4, 10)}
        for name in res[2]:
            digits = 2 if name.startswith("native") else 1
            print(f"{name:<28}" + "".join(f"{res[nx][name]:>12.{digits}f}" for nx in (2, 4, 10)))
        print(f"{'kalman_step / filterpy (given)':<28}" + "".join(
            f"{res[nx]['lpvest kalman_step (given)'] / res[nx]['filterpy (matrices given)']:>12.2f}"
            for nx in (2, 4, 10)))
        print(f"{'step / filterpy (given)':<28}" + "".join(
            f"{res[nx]['lpvest step'] / res[nx]['filterpy (matrices given)']:>12.2f}" for nx in (2, 4, 10)))
        print(f"{'step / filterpy + at(p)':<28}" + "".join(
            f"{res[nx]['lpvest step'] / res[nx]['filterpy + model.at(p)']:>12.2f}" for nx in (2, 4, 10)))
        print(f"{'step / native doStep':<28}" + "".join(
            f"{res[nx]['lpvest step'] / res[nx]['native FMU doStep (C host)']:>12.0f}" for nx in (2, 4, 10)))
        for num, den in (
            ("lpvest step", "lpvest batch (auto)"),
            ("lpvest run_streaming", "lpvest batch (auto)"),
            ("lpvest step", "lpvest batch (sequential)"),
            ("lpvest batch (sequential)", "lpvest batch (scan)"),
        ):
            label = f"{num[7:]} / {den[7:]}"
            print(f"{label:<28}" + "".join(f"{res[nx][num] / res[nx][den]:>12.2f}" for nx in (2, 4, 10)))

    print(f"\nwith a cross-covariance S != 0 (no filterpy row), {args.steps} steps, us per step:")
    print(f"{'':22}" + "".join(f"{'n_x = ' + str(n):>12}" for n in (2, 4, 10)))
    for ny in args.ny:
        cr = {nx: bench_cross(nx, ny, args.steps, args.repeat, args.seed) for nx in (2, 4, 10)}
        for name in cr[2]:
            print(f"n_y = {ny}  {name:<12}" + "".join(f"{cr[nx][name]:>12.1f}" for nx in (2, 4, 10)))
        print(f"n_y = {ny}  {'step / auto':<12}" + "".join(f"{cr[nx]['step'] / cr[nx]['auto']:>12.2f}"
                                                      for nx in (2, 4, 10)))

    print(f"\nscan vs sequential per call (ms) against T, n_y = 1 (best of {args.repeat}):")
    print(f"{'':14}" + "".join(f"{'T = ' + str(T):>16}" for T in args.crossover))
    for nx in (2, 10):
        cr = bench_methods(nx, 1, args.crossover, args.repeat, args.seed)
        for mt in ("sequential", "scan"):
            print(f"n_x = {nx:<3}{mt:>10}" + "".join(f"{1e3 * cr[T][mt]:>16.3f}" for T in args.crossover))
    print(f"\nscan vs sequential for larger n_x, n_y = 2, T = {args.steps} (us per step):")
    for nx in args.large:
        cr = bench_methods(nx, 2, [args.steps], max(2, args.repeat // 2), args.seed)[args.steps]
        print(f"  n_x = {nx:<4} sequential {1e6 * cr['sequential'] / args.steps:8.1f}   "
              f"scan {1e6 * cr['scan'] / args.steps:8.1f}   ratio {cr['sequential'] / cr['scan']:6.2f}")

    steps = max(args.steps // 10, 20)
    tr = bench_truncated(4, 1, args.taus, steps, args.repeat, args.seed)
    print(f"\nTruncatedKalmanFilter.step, n_x = 4, n_y = 1, {steps} steps (cost O(tau))")
    for tau, us in tr.items():
        print(f"  tau = {tau:<4} {us:10.1f} us/step   {us / (tau + 1):8.1f} us per window sample (tau + 1)")


if __name__ == "__main__":
    main()
