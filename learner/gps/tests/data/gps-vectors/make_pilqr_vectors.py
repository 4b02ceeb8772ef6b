#!/usr/bin/env python3
"""Records PI2 / PILQR reference vectors from the GPS codebase (cbfinn/gps).

Our own harness: it builds seeded synthetic problems, hands them to GPS's unmodified
`TrajOptPI2`, `TrajOptPILQR`, `approximated_cost` and `AlgorithmTrajOptPILQR._stepadjust`, and
writes their inputs and outputs as JSON (floats by Python repr, so they parse back to the same
f64). GPS's code is imported from the folder given on the command line; none of it is copied
here.

    python make_pilqr_vectors.py GPS_PYTHON_DIR OUT_DIR

GPS_PYTHON_DIR is GPS's `python/` folder at commit 82fa6cc930c4392d55d2525f6b792089f1d2ccfe.
GPS is Python 2 code; three shims let Python 3 import it without touching it: `xrange` is
`range`, `cPickle` is `pickle`, and `gps.proto.gps_pb2` (generated protobuf, only its
constants are read on this path) is a stand-in module whose names are ints.
"""
import builtins
import copy
import json
import os
import pickle
import platform
import sys
import types

import numpy as np
import scipy
import scipy.linalg

GPS_COMMIT = "82fa6cc930c4392d55d2525f6b792089f1d2ccfe"


def import_gps(path):
    builtins.xrange = range
    sys.modules["cPickle"] = pickle
    pb = types.ModuleType("gps.proto.gps_pb2")
    pb.__getattr__ = lambda name: "pb_" + name
    proto = types.ModuleType("gps.proto")
    proto.gps_pb2 = pb
    sys.modules["gps.proto"] = proto
    sys.modules["gps.proto.gps_pb2"] = pb
    sys.path.insert(0, path)
    import gps.algorithm.algorithm_traj_opt_pilqr as alg_pilqr
    import gps.algorithm.traj_opt.traj_opt_pilqr as to_pilqr
    import gps.algorithm.traj_opt.traj_opt_pi2 as to_pi2
    import gps.algorithm.traj_opt.traj_opt_utils as utils
    import gps.algorithm.policy.lin_gauss_policy as lgp
    import gps.algorithm.algorithm_utils as au
    import gps.algorithm.config as alg_config
    import gps.algorithm.traj_opt.config as to_config
    from gps.proto.gps_pb2 import NOISE

    return types.SimpleNamespace(
        AlgorithmTrajOptPILQR=alg_pilqr.AlgorithmTrajOptPILQR,
        TrajOptPILQR=to_pilqr.TrajOptPILQR,
        TrajOptPI2=to_pi2.TrajOptPI2,
        approximated_cost=utils.approximated_cost,
        LinearGaussianPolicy=lgp.LinearGaussianPolicy,
        IterationData=au.IterationData,
        TrajectoryInfo=au.TrajectoryInfo,
        ALG=alg_config.ALG,
        ALG_PILQR=alg_config.ALG_PILQR,
        TRAJ_OPT_PI2=to_config.TRAJ_OPT_PI2,
        NOISE=NOISE,
    )


def js(a):
    """numpy -> nested lists of Python floats (repr on output)."""
    if isinstance(a, np.ndarray):
        return a.astype(float).tolist()
    if isinstance(a, (np.floating, float)):
        return float(a)
    if isinstance(a, (np.integer, int)):
        return int(a)
    if isinstance(a, dict):
        return {k: js(v) for k, v in a.items()}
    if isinstance(a, (list, tuple)):
        return [js(v) for v in a]
    return a


def controller_dict(pol):
    return {
        "K": js(pol.K),
        "k": js(pol.k),
        "pol_covar": js(pol.pol_covar),
        "chol_pol_covar": js(pol.chol_pol_covar),
        "inv_pol_covar": js(pol.inv_pol_covar),
    }


def make_policy(G, K, k, pS):
    T, dU, _ = pS.shape
    cpS = np.zeros_like(pS)
    ipS = np.zeros_like(pS)
    for t in range(T):
        cpS[t] = scipy.linalg.cholesky(pS[t])  # upper, as GPS
        ipS[t] = np.linalg.inv(pS[t])
    return G.LinearGaussianPolicy(K, k, pS, cpS, ipS)


def spd(rng, d, scale):
    a = rng.standard_normal((d, d))
    return scale * (a @ a.T / d + 0.5 * np.eye(d))


class Sample:
    """What GPS's SampleList reads from a sample: X, U and the noise."""

    def __init__(self, X, U, noise, noise_key):
        self._X, self._U, self._noise, self._key = X, U, noise, noise_key

    def get_X(self):
        return self._X

    def get_U(self):
        return self._U

    def get(self, key):
        assert key == self._key
        return self._noise


class Cost:
    """c(x,u) = ½ Σ wx (x − tgt)² + ½ Σ wu u² + α Σ_r cos(V_r·[x;u] + b_r), analytic
    derivatives (the same form as the LQR vectors' cost). Not part of GPS."""

    def __init__(self, wx, tgt, wu, alpha, V, b):
        self.wx, self.tgt, self.wu, self.alpha, self.V, self.b = wx, tgt, wu, alpha, V, b

    def value(self, y, dX):
        x, u = y[:dX], y[dX:]
        c = 0.5 * np.sum(self.wx * (x - self.tgt) ** 2) + 0.5 * np.sum(self.wu * u**2)
        return c + self.alpha * np.sum(np.cos(self.V @ y + self.b))

    def eval(self, sample):
        X, U = sample.get_X(), sample.get_U()
        T, dX = X.shape
        dU = U.shape[1]
        l = np.zeros(T)
        lx = np.zeros((T, dX))
        lu = np.zeros((T, dU))
        lxx = np.zeros((T, dX, dX))
        luu = np.zeros((T, dU, dU))
        lux = np.zeros((T, dU, dX))
        for t in range(T):
            y = np.r_[X[t], U[t]]
            z = self.V @ y + self.b
            l[t] = self.value(y, dX)
            g = np.r_[self.wx * (X[t] - self.tgt), self.wu * U[t]] - self.alpha * self.V.T @ np.sin(z)
            H = np.diag(np.r_[self.wx, self.wu]) - self.alpha * (self.V.T * np.cos(z)) @ self.V
            lx[t], lu[t] = g[:dX], g[dX:]
            lxx[t], luu[t], lux[t] = H[:dX, :dX], H[dX:, dX:], H[dX:, :dX]
        return l, lx, lu, lxx, luu, lux


def problem(G, name, seed, T, dX, dU, N, cons_per_step, alpha):
    rng = np.random.default_rng(seed)
    dt = 0.1
    # True plant: a damped chain of double integrators plus a mild nonlinearity (so that the
    # linear model below is wrong and the residual cost is not zero).
    A = np.eye(dX) + dt * 0.3 * rng.standard_normal((dX, dX))
    B = dt * rng.standard_normal((dX, dU))
    c = 0.01 * rng.standard_normal(dX)
    nonlin = 0.05
    proc_std = 0.01

    def plant(x, u):
        return A @ x + B @ u + c + nonlin * np.sin(x) + proc_std * rng.standard_normal(dX)

    # Linear model the optimiser believes: the plant linearised at 0 plus a model error.
    Fm = np.zeros((T, dX, dX + dU))
    fv = np.zeros((T, dX))
    dyn_covar = np.zeros((T, dX, dX))
    for t in range(T - 1):
        Fm[t] = np.c_[A + nonlin * np.eye(dX), B] + 0.02 * rng.standard_normal((dX, dX + dU))
        fv[t] = c + 0.005 * rng.standard_normal(dX)
        dyn_covar[t] = proc_std**2 * np.eye(dX) + 1e-5 * spd(rng, dX, 1.0)

    # Controller executed this iteration.
    K = 0.3 * rng.standard_normal((T, dU, dX))
    k = 0.2 * rng.standard_normal((T, dU))
    pS = np.stack([spd(rng, dU, 0.1) for _ in range(T)])
    pol = make_policy(G, K, k, pS)

    x0mu = 0.5 * rng.standard_normal(dX)
    x0std = 0.02
    X = np.zeros((N, T, dX))
    U = np.zeros((N, T, dU))
    noise = rng.standard_normal((N, T, dU))
    for i in range(N):
        x = x0mu + x0std * rng.standard_normal(dX)
        for t in range(T):
            X[i, t] = x
            U[i, t] = pol.act(x, None, t, noise[i, t])
            x = plant(x, U[i, t])
    samples = [Sample(X[i], U[i], noise[i], G.NOISE) for i in range(N)]

    r = 3
    cost = Cost(
        wx=rng.uniform(0.5, 2.0, dX),
        tgt=0.3 * rng.standard_normal(dX),
        wu=rng.uniform(0.05, 0.2, dU),
        alpha=alpha,
        V=rng.standard_normal((r, dX + dU)),
        b=rng.uniform(0, 2 * np.pi, r),
    )

    from gps.sample.sample_list import SampleList

    sample_list = SampleList(samples)

    info = G.TrajectoryInfo()
    info.dynamics = types.SimpleNamespace(Fm=Fm, fv=fv, dyn_covar=dyn_covar)
    info.x0mu = np.mean(X[:, 0, :], axis=0)
    info.x0sigma = np.diag(np.maximum(np.var(X[:, 0, :], axis=0), 1e-6))

    # GPS algorithm state without the agent and samplers (`__init__` needs them): the
    # attributes AlgorithmTrajOptPILQR and TrajOptPILQR read.
    hp = copy.deepcopy(G.ALG)
    hp.update(copy.deepcopy(G.ALG_PILQR))
    if cons_per_step:
        kl_step = np.linspace(0.4, 0.2, T)
        hp.update(
            kl_step=kl_step,
            max_step_mult=np.linspace(10.0, 5.0, T),
            min_step_mult=np.linspace(0.01, 0.5, T),
        )
    else:
        hp.update(kl_step=0.2, max_step_mult=10.0, min_step_mult=0.01)
    traj_opt_hp = {"cons_per_step": cons_per_step}

    alg = G.AlgorithmTrajOptPILQR.__new__(G.AlgorithmTrajOptPILQR)
    alg._hyperparams = hp
    alg.M, alg.T, alg.dX, alg.dU = 1, T, dX, dU
    alg.iteration_count = 1
    alg.cost = [cost]
    alg.base_kl_step = hp["kl_step"]
    alg.traj_opt = G.TrajOptPILQR(traj_opt_hp)
    cur = G.IterationData()
    cur.sample_list = sample_list
    cur.traj_info = info
    cur.traj_distr = pol
    cur.step_mult = 1.0
    cur.eta = 1.0
    alg.cur = [cur]
    alg._eval_cost(0)

    out = {
        "meta": {
            "problem": name,
            "gps_commit": GPS_COMMIT,
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "python": platform.python_version(),
            "seed": seed,
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
            "note": "Produced by make_pilqr_vectors.py running unmodified GPS code; see README.md",
        },
        "dims": {"T": T, "dX": dX, "dU": dU, "N": N},
        "hyperparams": {
            "traj_opt": {"cons_per_step": cons_per_step},
            "pi2": js(G.TRAJ_OPT_PI2),
            "algorithm": {
                "kl_step": js(hp["kl_step"]),
                "min_step_mult": js(hp["min_step_mult"]),
                "max_step_mult": js(hp["max_step_mult"]),
                "step_rule": hp["step_rule"],
                "step_rule_res_ratio_dec": hp["step_rule_res_ratio_dec"],
                "step_rule_res_ratio_inc": hp["step_rule_res_ratio_inc"],
                "max_ent_traj": hp["max_ent_traj"],
            },
        },
        "inputs": {
            "X": js(X),
            "U": js(U),
            "noise": js(noise),
            "controller": controller_dict(pol),
            "dynamics": {"Fm": js(Fm), "fv": js(fv), "dyn_covar": js(dyn_covar)},
            "x0mu": js(info.x0mu),
            "x0sigma": js(info.x0sigma),
            "cost": {"cc": js(info.cc), "cv": js(info.cv), "Cm": js(info.Cm)},
            "cs": js(cur.cs),
            "eta_start": 1.0,
            "step_mult": 1.0,
        },
    }

    # approximated_cost with the executed controller (the step rule's and PILQR's prediction).
    mu_all, c_approx = G.approximated_cost(sample_list, pol, info)
    out["approximated_cost"] = {"mu": js(mu_all), "predicted_cost": js(c_approx)}

    # TrajOptPILQR.update: the LQR step, then PI2 twice (temperature from the sampled cost,
    # then the update on the residual cost at that temperature). The PI2 calls' outputs are
    # recorded by wrapping the instance's method (GPS's code runs unchanged).
    pi2_calls = []
    opt = alg.traj_opt
    inner = opt.traj_opt_pi2.update

    def recording_update(m, algorithm, **kw):
        distr, eta = inner(m, algorithm, **kw)
        pi2_calls.append({"kwargs": {k: v for k, v in kw.items() if k != "costs"},
                          "eta": eta, "k": distr.k})
        return distr, eta

    opt.traj_opt_pi2.update = recording_update
    lqr_distr, lqr_eta = G.TrajOptPILQR.__mro__[1].update(copy.deepcopy(opt), 0, alg)
    new_distr, eta = opt.update(0, alg)
    assert alg.cur[0].traj_distr is pol
    out["pilqr_update"] = {
        "note": "TrajOptPILQR.update(0, alg) on the inputs: lqr_* is TrajOptLQRPython.update alone "
        "(the first half), residual_cost = cs - approximated_cost(samples, controller, info), "
        "eta_pi2 the per-step temperatures of the first PI2 call (on cs), controller the result",
        "lqr_eta": js(lqr_eta),
        "lqr_controller": controller_dict(lqr_distr),
        "residual_cost": js(cur.cs - c_approx),
        "eta_pi2": js(pi2_calls[0]["eta"]),
        "eta": js(eta),
        "controller": controller_dict(new_distr),
    }

    # _stepadjust with the res_percent rule (what only needs cur; prev must exist for GPS).
    alg.prev = [copy.deepcopy(cur)]
    cases = []
    for step_mult, dec, inc in ((1.0, 0.2, 0.05), (0.02, 1e-3, 1e-4), (9.0, 0.99, 0.9), (0.3, 0.99, 0.9)):
        a2 = copy.copy(alg)
        a2._hyperparams = dict(alg._hyperparams, step_rule_res_ratio_dec=dec, step_rule_res_ratio_inc=inc)
        c2 = copy.copy(cur)
        c2.step_mult = (np.ones(T) * step_mult) if cons_per_step else step_mult
        a2.cur = [c2]
        a2.prev = [copy.copy(cur)]
        a2.prev[0].step_mult = c2.step_mult
        before = copy.copy(c2.step_mult)
        G.AlgorithmTrajOptPILQR._stepadjust(a2, 0)
        cases.append({"step_rule_res_ratio_dec": dec, "step_rule_res_ratio_inc": inc,
                      "step_mult_before": js(before), "step_mult_after": js(c2.step_mult)})
    out["step_rule_res_percent"] = {
        "note": "AlgorithmTrajOptPILQR._stepadjust on the inputs (cur = executed controller, "
        "its samples and cs); cur_res = approximated_cost - cs",
        "cases": cases,
    }

    # Unit cases of TrajOptPI2.update_pi2 on random policy samples and costs.
    pi2_cases = []
    S = 12
    for case, (kl_threshold, damping, fixed) in enumerate(
        [(1.0, 2.0, None), (0.5, 0.0, None), (2.0, 2.0, None), (1.0, 2.0, "array"), (1.0, 1.0, "scalar")]
    ):
        hp2 = {"kl_threshold": kl_threshold, "covariance_damping": damping}
        pi2 = G.TrajOptPI2(hp2)
        samp = rng.standard_normal((S, T, dU)) * 0.3 + 0.1
        costs = rng.gamma(2.0, 1.0, (S, T)) + 0.5 * samp[:, :, 0] ** 2
        mean_old = 0.1 * rng.standard_normal((T, dU))
        cov_old = np.stack([spd(rng, dU, 0.2) for _ in range(T)])
        if fixed == "array":
            fixed_eta = rng.uniform(0.5, 5.0, T)
        elif fixed == "scalar":
            fixed_eta = 2.5
        else:
            fixed_eta = None
        fixed_in = copy.copy(fixed_eta)
        m, cov, icov, ccov, etas = pi2.update_pi2(
            samp, costs, mean_old, cov_old, fixed_eta=fixed_eta, use_fixed_eta=fixed is not None
        )
        dual = None
        if fixed is None:
            dual = [
                float(pi2.kl_dual(etas[t], kl_threshold, np.sum(costs[:, t:], axis=1)))
                for t in range(T)
            ]
        pi2_cases.append(
            {
                "kl_threshold": kl_threshold,
                "covariance_damping": damping,
                "min_temperature": pi2._min_temperature,
                "fixed_eta": js(fixed_in),
                "samples": js(samp),
                "costs": js(costs),
                "mean_old": js(mean_old),
                "cov_old": js(cov_old),
                "mean_new": js(m),
                "cov_new": js(cov),
                "inv_cov_new": js(icov),
                "chol_cov_new": js(ccov),
                "etas": js(etas),
                "kl_dual_at_etas": dual,
            }
        )
    out["pi2_update"] = {
        "note": "TrajOptPI2.update_pi2(samples (S,T,dU), costs (S,T), mean_old, cov_old, fixed_eta, "
        "use_fixed_eta = fixed_eta is not null); etas is GPS's returned array (zeros when fixed); "
        "without a fixed eta, etas are scipy L-BFGS-B minimisers of kl_dual from 10.0, and "
        "kl_dual_at_etas the dual's value there (per t, cost-to-go)",
        "cases": pi2_cases,
    }
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    G = import_gps(os.path.abspath(sys.argv[1]))
    out_dir = sys.argv[2]
    for name, seed, T, dX, dU, N, per_step, alpha in [
        ("pilqr_A", 11, 10, 4, 2, 5, False, 0.2),
        ("pilqr_B", 12, 20, 6, 3, 8, True, 0.05),
    ]:
        data = problem(G, name, seed, T, dX, dU, N, per_step, alpha)
        path = os.path.join(out_dir, name + ".json")
        with open(path, "w") as f:
            json.dump(data, f)
        print("wrote", path)


if __name__ == "__main__":
    main()
