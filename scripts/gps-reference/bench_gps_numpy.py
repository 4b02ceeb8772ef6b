#!/usr/bin/env python3
"""Times GPS's own numpy code on the inputs of a GPS reference-vectors file.

The counterpart of `learner bench --vectors FILE`: for each recorded iteration it runs, on
one BLAS thread, the three pieces that command times, with GPS's unmodified code
(cbfinn/gps, imported from the checkout given by --gps):

  GMM prior update    DynamicsLRPrior.update_prior -> DynamicsPriorGMM.update -> GMM.update,
                      the prior's dataset and GMM as GPS had them before the iteration (a fresh
                      GMM at iteration 0, else the previous iteration's, which EM warm-starts
                      from when K is unchanged), the cluster assignment drawn by GPS's own
                      np.random.randint after the recorded np.random.seed
  dynamics fit + x0   Algorithm._update_dynamics (DynamicsLRPrior.fit and the x0 fit) without
                      its prior update, which the previous row times
  eta search          TrajOptLQRPython.update from the recorded dynamics, x0, cost model,
                      previous controller, start eta and step multiplier

and prints the median thread CPU time (time.thread_time) of each piece over --reps
repetitions. With a file that records GPS's outputs, it first checks that GPS reproduces
them (clusters, EM iterations, eta-search passes, final eta, new controller, ...) and
refuses to report a time if not. A file without `outputs` ("inputs-only") is timed without
checks; each iteration then starts from what GPS computed for the previous one.

See README.md beside this file for the set-up and the file layout.
"""

import os

# One BLAS thread, before numpy is imported (also what the vectors were recorded with).
for _var in (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
):
    os.environ[_var] = "1"

import argparse
import contextlib
import copy
import gc
import hashlib
import json
import platform
import re
import statistics
import sys
import time
import types

import numpy as np
import scipy

PIECES = ("gmm_prior_update", "dynamics_fit", "eta_search")
ROW_NAMES = {
    "gmm_prior_update": "GMM prior update",
    "dynamics_fit": "dynamics fit + x0",
    "eta_search": "eta search",
    "total": "total",
}

# Tolerances of the checks against the recorded outputs (relative, see rel_err).
TOL_ETA = 1e-9  # final eta, and eta in/out of every backward pass
TOL_CONTROLLER = 1e-8  # new controller's K and k
TOL_KL_STEP = 1e-12  # KL target from the step multiplier
# Informative comparisons, checked with the tolerances the vectors' README suggests.
TOL_DYN_FM = 1e-6  # Fm, fv (depend on conditioning)
TOL_DYN_COVAR = 1e-8  # dyn_covar
TOL_X0 = 1e-9  # x0mu, x0sigma
TOL_GMM = 1e-6  # GMM mu, sigma, logmass after EM (README: about 1e-11 observed)
REL_FLOOR = 1e-3  # as gps::conformance::rel_err


class Refused(Exception):
    """GPS did not reproduce the recorded outputs, or the file cannot be run as GPS ran it."""


def rel_err(got, exp):
    """max_i |got_i - exp_i| / max(|exp_i|, REL_FLOOR * max_j |exp_j|), 0 where equal: the
    Rust checker's gps::conformance::rel_err."""
    got = np.asarray(got, dtype=float).ravel()
    exp = np.asarray(exp, dtype=float).ravel()
    if got.shape != exp.shape:
        return float("inf")
    if got.size == 0:
        return 0.0
    d = np.abs(got - exp)
    if np.any(np.isnan(d)):
        return float("inf")
    floor = max(REL_FLOOR * float(np.max(np.abs(exp))), sys.float_info.min)
    return float(np.max(np.where(d == 0, 0.0, d / np.maximum(np.abs(exp), floor))))


def blas_info():
    """BLAS libraries loaded and their threads (threadpoolctl, if installed)."""
    try:
        import threadpoolctl
    except ImportError:
        return None
    return [
        {
            k: lib.get(k)
            for k in ("internal_api", "version", "architecture", "num_threads", "filepath")
        }
        for lib in threadpoolctl.threadpool_info()
        if lib.get("user_api") == "blas"
    ]


def import_gps(gps_root):
    """Imports the GPS modules the pieces need from the checkout at gps_root.

    GPS is Python 2-era code. The only module on the import path of these pieces that does
    not load on Python 3 is gps.sample.sample_list (`import cPickle`, and the protobuf module
    gps.proto.gps_pb2 that GPS generates at build time); traj_opt_lqr_python imports it only
    through algorithm_badmm / algorithm_mdgps for the name SampleList, which these pieces do
    not use. It is stubbed in sys.modules; no GPS file is changed.
    """
    py = os.path.join(gps_root, "python")
    if not os.path.isfile(os.path.join(py, "gps", "utility", "gmm.py")):
        raise SystemExit(f"error: {gps_root} is not a GPS checkout (no python/gps/utility/gmm.py)")
    sys.path.insert(0, py)
    stub = types.ModuleType("gps.sample.sample_list")

    class SampleList:  # stands in for the name only
        pass

    stub.SampleList = SampleList
    sys.modules["gps.sample.sample_list"] = stub
    import gps.algorithm.config as alg_config
    import gps.algorithm.dynamics.config as dyn_config
    import gps.algorithm.traj_opt.config as opt_config
    import gps.algorithm.traj_opt.traj_opt_utils as opt_utils
    import gps.utility.gmm as gmm_mod
    from gps.algorithm.algorithm_traj_opt import AlgorithmTrajOpt
    from gps.algorithm.algorithm_utils import IterationData, TrajectoryInfo
    from gps.algorithm.dynamics.dynamics_lr_prior import DynamicsLRPrior
    from gps.algorithm.dynamics.dynamics_prior_gmm import DynamicsPriorGMM
    from gps.algorithm.policy.lin_gauss_policy import LinearGaussianPolicy
    from gps.algorithm.traj_opt.traj_opt_lqr_python import TrajOptLQRPython

    return types.SimpleNamespace(
        alg_config=alg_config,
        dyn_config=dyn_config,
        opt_config=opt_config,
        opt_utils=opt_utils,
        gmm_mod=gmm_mod,
        AlgorithmTrajOpt=AlgorithmTrajOpt,
        IterationData=IterationData,
        TrajectoryInfo=TrajectoryInfo,
        DynamicsLRPrior=DynamicsLRPrior,
        DynamicsPriorGMM=DynamicsPriorGMM,
        LinearGaussianPolicy=LinearGaussianPolicy,
        TrajOptLQRPython=TrajOptLQRPython,
    )


# Git blob ids of the GPS files these pieces import, at the commit that recorded the vectors.
GPS_COMMIT = "82fa6cc930c4392d55d2525f6b792089f1d2ccfe"
GPS_BLOBS = {
    "python/gps/__init__.py": "72fd8de61f6350aa9597f037dfd8bd32027d4736",
    "python/gps/algorithm/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/algorithm/algorithm.py": "d09954f09f83c42928755bbf2a8648b2602ddba4",
    "python/gps/algorithm/algorithm_badmm.py": "ce40e7d96cb1811856210207c88855c172ef62bc",
    "python/gps/algorithm/algorithm_mdgps.py": "378a3fa50401e07ecdf7ffc489a68fd6a1b3ca33",
    "python/gps/algorithm/algorithm_traj_opt.py": "3e9576e9809e9929823cdad5492d3020f9241051",
    "python/gps/algorithm/algorithm_utils.py": "fa3d465615bff69b6e621912ef5a9349d5e3130b",
    "python/gps/algorithm/config.py": "a247f3fdce32567f819a2e75abb1b688bdd90b02",
    "python/gps/algorithm/dynamics/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/algorithm/dynamics/config.py": "7bcff382bb166ac4825b2c55f4a446382d83a0f2",
    "python/gps/algorithm/dynamics/dynamics.py": "bfcdc87a7cabb3aa1a43a55332b9d866d2cc24a0",
    "python/gps/algorithm/dynamics/dynamics_lr_prior.py": "c3b57665126000043dbdf167411ac400f64fc8d8",
    "python/gps/algorithm/dynamics/dynamics_prior_gmm.py": "af920add19d0ed1dae3a03316ca42a3fdca2db1d",
    "python/gps/algorithm/policy/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/algorithm/policy/lin_gauss_policy.py": "12727822787c314649c0db4798564f7ff61c9ca0",
    "python/gps/algorithm/policy/policy.py": "7dcf706838b68b1d38b11950094454045366b553",
    "python/gps/algorithm/traj_opt/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/algorithm/traj_opt/config.py": "55a14486be23fea371957d5297fe687b58490302",
    "python/gps/algorithm/traj_opt/traj_opt.py": "e666ac56dd1acf3b80b14bf9085647cd2886cb26",
    "python/gps/algorithm/traj_opt/traj_opt_lqr_python.py": "07111e6105d9f2db531888646fdb743548e3aee4",
    "python/gps/algorithm/traj_opt/traj_opt_utils.py": "bd9c2bbd3fc81ef56afd80f48931bfe08b8daf44",
    "python/gps/sample/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/utility/__init__.py": "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391",
    "python/gps/utility/general_utils.py": "98cc3e49df280ef6f28b57e7177c635628b3f411",
    "python/gps/utility/gmm.py": "a110dc9f560575c439406f46c1ae0ec903ed1485",
}


def gps_files_differing(gps_root):
    """The imported GPS files whose contents are not those of GPS_COMMIT (git blob ids)."""
    root = os.path.realpath(gps_root)
    differing = []
    for mod in list(sys.modules.values()):
        f = getattr(mod, "__file__", None)
        if not f or not os.path.realpath(f).startswith(root + os.sep):
            continue
        rel = os.path.relpath(os.path.realpath(f), root)
        with open(f, "rb") as fh:
            body = fh.read()
        blob = hashlib.sha1(b"blob %d\0" % len(body) + body).hexdigest()
        if GPS_BLOBS.get(rel) != blob:
            differing.append(rel)
    return sorted(differing)


# --- what GPS's Algorithm reads of samples and costs ------------------------------------


class Sample:
    """One trajectory, with the accessors GPS's Algorithm uses (Sample.get_X / get_U)."""

    def __init__(self, x, u, derivs):
        self._x, self._u, self.derivs = x, u, derivs

    def get_X(self):
        return self._x

    def get_U(self):
        return self._u


class Samples:
    """The accessors of GPS's SampleList that the timed pieces use (get_X, get_U, len, [i])."""

    def __init__(self, x, u, derivs=None):
        self._x, self._u = x, u
        self._samples = [
            Sample(x[n], u[n], None if derivs is None else [d[n] for d in derivs])
            for n in range(x.shape[0])
        ]

    def get_X(self):
        return self._x

    def get_U(self):
        return self._u

    def __len__(self):
        return len(self._samples)

    def __getitem__(self, n):
        return self._samples[n]


class RecordedCost:
    """A GPS cost object whose eval(sample) returns the sample's recorded derivatives."""

    def eval(self, sample):
        return tuple(sample.derivs)


# --- the file ----------------------------------------------------------------------------


def arr(v, name):
    if v is None:
        raise Refused(f"{name} is missing")
    return np.asarray(v, dtype=float)


def controller(g, d, name):
    """A LinearGaussianPolicy from a controller dict of the file."""
    if not isinstance(d, dict):
        raise Refused(f"{name} is not a controller dict")
    return g.LinearGaussianPolicy(
        arr(d.get("K"), name + ".K"),
        arr(d.get("k"), name + ".k"),
        arr(d.get("pol_covar"), name + ".pol_covar"),
        arr(d.get("chol_pol_covar"), name + ".chol_pol_covar"),
        arr(d.get("inv_pol_covar"), name + ".inv_pol_covar"),
    )


def settings(g, hp):
    """GPS's config dicts for the pieces: GPS's defaults updated with the file's hyperparams."""
    alg = copy.deepcopy(g.alg_config.ALG)
    for k, v in (hp.get("algorithm") or {}).items():
        if k in alg:
            alg[k] = v
    opt = {k: v for k, v in (hp.get("traj_opt") or {}).items() if k in g.opt_config.TRAJ_OPT_LQR}
    # Constants GPS hard-codes in traj_opt_utils / TrajOptLQRPython._conv_check.
    hp_opt = hp.get("traj_opt") or {}
    if hp_opt.get("DGD_MAX_ITER", g.opt_utils.DGD_MAX_ITER) != g.opt_utils.DGD_MAX_ITER:
        raise Refused(
            f"traj_opt.DGD_MAX_ITER {hp_opt['DGD_MAX_ITER']} is not GPS's {g.opt_utils.DGD_MAX_ITER}"
        )
    if hp_opt.get("conv_tol_rel", 0.1) != 0.1:
        raise Refused(f"traj_opt.conv_tol_rel {hp_opt['conv_tol_rel']} is not GPS's 0.1")
    dyn_hp = hp.get("dynamics") or {}
    prior = copy.deepcopy(g.dyn_config.DYN_PRIOR_GMM)
    prior.update(dyn_hp.get("prior") or {})
    prior["type"] = g.DynamicsPriorGMM
    dynamics = {"type": g.DynamicsLRPrior, "prior": prior}
    # DynamicsLRPrior has no default; 1e-6 is what GPS's example experiments set.
    dynamics["regularization"] = dyn_hp.get("regularization", 1e-6)
    return alg, opt, dynamics


def make_algorithm(g, alg_hp, opt_hp, t, dx, du):
    """An AlgorithmTrajOpt for one condition with what the pieces read (its __init__ needs an
    agent and cost objects; only the attributes set here are used by the timed methods)."""
    a = g.AlgorithmTrajOpt.__new__(g.AlgorithmTrajOpt)
    a._hyperparams = copy.deepcopy(alg_hp)
    a.M = 1
    a._cond_idx = [0]
    a.iteration_count = 0
    a.T, a.dX, a.dU = t, dx, du
    a.cur = [g.IterationData()]
    a.prev = [g.IterationData()]
    a.cur[0].traj_info = g.TrajectoryInfo()
    a.prev[0].traj_info = g.TrajectoryInfo()
    a.traj_opt = g.TrajOptLQRPython(copy.deepcopy(opt_hp))
    a.cost = [RecordedCost()]
    a.base_kl_step = a._hyperparams["kl_step"]
    return a


def traj_info(g, dyn, x0mu, x0sigma, cc, cv, cm):
    ti = g.TrajectoryInfo()
    ti.dynamics = dyn
    ti.x0mu, ti.x0sigma = x0mu, x0sigma
    ti.cc, ti.cv, ti.Cm = cc, cv, cm
    return ti


def recorded_traj_info(g, out):
    d, c = out["dynamics"], out["cost"]
    dyn = types.SimpleNamespace(
        Fm=arr(d["Fm"], "dynamics.Fm"),
        fv=arr(d["fv"], "dynamics.fv"),
        dyn_covar=arr(d["dyn_covar"], "dynamics.dyn_covar"),
    )
    return traj_info(
        g,
        dyn,
        arr(out["x0mu"], "x0mu"),
        arr(out["x0sigma"], "x0sigma"),
        arr(c["cc"], "cost.cc"),
        arr(c["cv"], "cost.cv"),
        arr(c["Cm"], "cost.Cm"),
    )


class GivenClusters:
    """Makes GPS's GMM.update draw the given initial cluster assignment.

    GMM.update draws it with np.random.randint(0, K, size=(1, N)); for a file that gives the
    assignment instead of (or without) a legacy-RNG seed, gps.utility.gmm's module-global
    `np` is swapped, for the duration of the update only, for a copy of numpy whose
    random.randint returns the assignment. Every other numpy name is the same object.
    """

    def __init__(self, gmm_mod, idx):
        self.gmm_mod, self.idx = gmm_mod, idx
        fake = types.ModuleType("numpy")
        fake.__dict__.update(np.__dict__)
        fake.random = types.SimpleNamespace(randint=self._randint)
        self.fake = fake

    def _randint(self, low, high, size=None):
        if self.idx is None:
            raise Refused(
                "GPS's GMM (re)initialised its clusters, and the file gives neither "
                "inputs.gmm_legacy_np_random_seed nor an initial cluster assignment"
            )
        idx = np.asarray(self.idx, dtype=np.int64).reshape(1, -1)
        if low != 0 or tuple(size) != idx.shape or idx.min() < 0 or idx.max() >= high:
            raise Refused(
                f"the given init_cluster_idx ({idx.shape[1]} points in [0, {idx.max() + 1})) "
                f"does not fit GPS's draw of size {size} in [0, {high})"
            )
        return idx.copy()

    def __enter__(self):
        self.gmm_mod.np = self.fake

    def __exit__(self, *exc):
        self.gmm_mod.np = np


# --- one iteration -----------------------------------------------------------------------


class Iteration:
    """Everything one recorded iteration's three pieces start from."""

    def __init__(self, index, inp, out):
        self.index, self.inp, self.out = index, inp, out


def gmm_state(g, gmm_dict_or_obj):
    """A GPS GMM holding a previous iteration's parameters (or a fresh one for None)."""
    gmm = g.gmm_mod.GMM()
    src = gmm_dict_or_obj
    if src is None:
        return gmm
    if isinstance(src, dict):
        k = int(src["K"])
        gmm.mu = arr(src["mu"], "gmm.mu").reshape(k, -1)
        gmm.sigma = arr(src["sigma"], "gmm.sigma").reshape(k, gmm.mu.shape[1], gmm.mu.shape[1])
        gmm.logmass = arr(src["logmass"], "gmm.logmass").reshape(k, 1)
        mass = src.get("mass")
        gmm.mass = np.exp(gmm.logmass) if mass is None else arr(mass, "gmm.mass").reshape(k, 1)
        gmm.N = int(src["self_N"])
    else:
        gmm.mu, gmm.sigma = src.mu.copy(), src.sigma.copy()
        gmm.logmass, gmm.mass, gmm.N = src.logmass.copy(), src.mass.copy(), src.N
    return gmm


class Runner:
    def __init__(self, g, data, reps):
        self.g, self.reps = g, reps
        dims = data["dims"]
        self.t, self.dx, self.du = int(dims["T"]), int(dims["dX"]), int(dims["dU"])
        hp = data.get("hyperparams") or {}
        self.alg_hp, self.opt_hp, self.dyn_hp = settings(g, hp)
        self.init_controller = controller(g, data.get("init_controller"), "init_controller")
        its = data.get("iterations") or []
        if not its:
            raise Refused("the file has no iterations")
        self.iterations = [
            Iteration(i, it.get("inputs"), it.get("outputs")) for i, it in enumerate(its)
        ]
        with_out = [it.out is not None for it in self.iterations]
        if any(with_out) and not all(with_out):
            raise Refused("some iterations record outputs and others not")
        self.checked = all(with_out)
        # What each iteration leaves for the next (its GMM, new controller, traj_info, cs).
        self.done = []

    # The state before iteration i, as GPS had it.

    def earlier_dataset(self, i):
        """The prior's X, U before iteration i: the earlier samples, trimmed as GPS trims."""
        x, u = None, None
        max_samples = self.dyn_hp["prior"]["max_samples"]
        for it in self.iterations[:i]:
            xi, ui = self.x_u(it)
            x = xi if x is None else np.concatenate([x, xi], axis=0)
            u = ui if u is None else np.concatenate([u, ui], axis=0)
            start = max(0, x.shape[0] - max_samples + 1)
            x, u = x[start:], u[start:]
        return x, u

    def x_u(self, it):
        x = arr(it.inp.get("X"), f"iterations[{it.index}].inputs.X")
        u = arr(it.inp.get("U"), f"iterations[{it.index}].inputs.U")
        if x.shape[1:] != (self.t, self.dx) or u.shape[1:] != (self.t, self.du):
            raise Refused(f"iterations[{it.index}]: X or U does not have the dims' shape")
        return x, u

    def previous_gmm(self, i):
        if i == 0:
            return None
        if self.checked:
            return self.iterations[i - 1].out["gmm"]
        return self.done[i - 1]["gmm"]

    def prev_controller(self, it):
        ref = it.inp.get("prev_controller")
        if ref == "init_controller":
            return self.init_controller
        if isinstance(ref, dict):
            return controller(self.g, ref, f"iterations[{it.index}].inputs.prev_controller")
        m = re.fullmatch(r"iterations\[(\d+)\]\.outputs\.new_controller", str(ref))
        if not m or int(m.group(1)) >= it.index:
            raise Refused(
                f"iterations[{it.index}].inputs.prev_controller {ref!r} is not understood"
            )
        j = int(m.group(1))
        if self.checked:
            return controller(self.g, self.iterations[j].out["new_controller"], ref)
        return self.done[j]["new_controller"]

    def cluster_init(self, it):
        """(seed, given assignment) for GPS's GMM initialisation in this iteration."""
        seed = it.inp.get("gmm_legacy_np_random_seed")
        given = it.inp.get("init_cluster_idx")
        if given is None and seed is None and self.checked:
            given = (it.out.get("gmm") or {}).get("init_cluster_idx")
        return seed, given

    def fresh_state(self, it, samples):
        """A DynamicsLRPrior and an Algorithm as GPS had them before the iteration."""
        g = self.g
        dyn = g.DynamicsLRPrior(copy.deepcopy(self.dyn_hp))
        x, u = self.earlier_dataset(it.index)
        dyn.prior.X, dyn.prior.U = x, u
        dyn.prior.gmm = gmm_state(g, self.previous_gmm(it.index))
        alg = make_algorithm(g, self.alg_hp, self.opt_hp, self.t, self.dx, self.du)
        alg.cur[0].sample_list = samples
        alg.cur[0].traj_info.dynamics = dyn
        return dyn, alg

    def cost_model(self, it, samples, alg):
        """(cc, cv, Cm, cs) of an inputs-only iteration: inputs.cost, or GPS's _eval_cost of
        the per-sample derivatives (cost_derivs_per_sample). Not timed, as in our bench."""
        c = it.inp.get("cost")
        if c is not None:
            cs = c.get("cs")
            return (
                arr(c.get("cc"), "inputs.cost.cc"),
                arr(c.get("cv"), "inputs.cost.cv"),
                arr(c.get("Cm"), "inputs.cost.Cm"),
                None if cs is None else arr(cs, "inputs.cost.cs"),
            )
        if samples[0].derivs is None:
            raise Refused(
                f"iterations[{it.index}]: no cost model (neither inputs.cost nor cost_derivs_per_sample)"
            )
        alg._eval_cost(0)
        ti = alg.cur[0].traj_info
        return ti.cc, ti.cv, ti.Cm, alg.cur[0].cs

    def samples(self, it):
        x, u = self.x_u(it)
        cd = it.inp.get("cost_derivs_per_sample")
        derivs = None
        if cd is not None:
            derivs = [
                arr(cd[k], f"cost_derivs_per_sample.{k}")
                for k in ("l", "lx", "lu", "lxx", "luu", "lux")
            ]
        return Samples(x, u, derivs)

    def step_mult(self, it, info, prev_ctrl, cs):
        """GPS's step multiplier for the η search: step_mult_start at iteration 0, else
        Algorithm._stepadjust (previous vs predicted vs actual Laplace cost)."""
        g = self.g
        start = float(it.inp.get("step_mult_start", 1.0))
        if it.index == 0:
            return start
        before = self.done[it.index - 1]
        a = make_algorithm(g, self.alg_hp, self.opt_hp, self.t, self.dx, self.du)
        a.iteration_count = it.index
        a.prev[0].traj_distr = before["prev_controller"]
        a.prev[0].traj_info = before["info"]
        a.prev[0].cs = before["cs"] if before["cs"] is not None else np.zeros((1, self.t))
        a.cur[0].traj_distr = prev_ctrl
        a.cur[0].traj_info = info
        a.cur[0].cs = cs if cs is not None else np.zeros((1, self.t))
        a.cur[0].step_mult = start
        a._stepadjust(0)
        return a.cur[0].step_mult

    def eta_algorithm(self, it, info, prev_ctrl, step_mult):
        a = make_algorithm(self.g, self.alg_hp, self.opt_hp, self.t, self.dx, self.du)
        a.cur[0].traj_info = info
        a.cur[0].traj_distr = prev_ctrl
        a.cur[0].eta = float(it.inp["eta_start"])
        a.cur[0].step_mult = step_mult
        return a

    def clusters(self, seed, given):
        """Before a prior update: seeds numpy's legacy RNG, which GPS's GMM draws its initial
        clusters from, or returns the context that hands GPS the given assignment."""
        if given is None and seed is not None:
            np.random.seed(int(seed))
            return contextlib.nullcontext()
        return GivenClusters(self.g.gmm_mod, given)

    def fit_only(self, it, samples, seed, given):
        """GPS's prior update and dynamics + x0 fit, untimed (an inputs-only iteration's η
        search runs on what GPS fits here)."""
        dyn, alg = self.fresh_state(it, samples)
        with self.clusters(seed, given):
            dyn.update_prior(samples)
        dyn.update_prior = lambda _samples: None
        alg._update_dynamics()
        ti = alg.cur[0].traj_info
        return dyn, ti.x0mu, ti.x0sigma

    def one_rep(self, it, samples, seed, given, info, prev_ctrl, step_mult, count=False):
        """One run of the three pieces: (cpu s, wall s) per piece and what GPS computed. With
        count, GPS's methods are wrapped (on the instances) to count EM iterations and record
        the backward passes; that run is not one of the timed repetitions."""
        dyn, alg = self.fresh_state(it, samples)
        eta_alg = self.eta_algorithm(it, info, prev_ctrl, step_mult)
        gmm = dyn.prior.gmm
        stats = {"estep_calls": 0, "backward": []}
        if count:
            estep = gmm.estep

            def counting_estep(data):
                stats["estep_calls"] += 1
                return estep(data)

            gmm.estep = counting_estep
            backward = eta_alg.traj_opt.backward

            def recording_backward(prev, ti, eta, algorithm, m):
                res = backward(prev, ti, eta, algorithm, m)
                stats["backward"].append((eta, res[1]))
                return res

            eta_alg.traj_opt.backward = recording_backward
        update_prior = dyn.update_prior
        clusters = self.clusters(seed, given)
        gc.collect()
        # GMM prior update.
        c0, w0 = time.thread_time(), time.perf_counter()
        with clusters:
            update_prior(samples)
        c1, w1 = time.thread_time(), time.perf_counter()
        if count:
            # EM's E-steps only (the prior's evaluation in the fit runs E-steps too).
            del gmm.estep
        # Dynamics fit + x0: GPS's _update_dynamics without its prior update (timed above).
        dyn.update_prior = lambda _samples: None
        c2, w2 = time.thread_time(), time.perf_counter()
        alg._update_dynamics()
        c3, w3 = time.thread_time(), time.perf_counter()
        # η search.
        new_ctrl, eta = eta_alg.traj_opt.update(0, eta_alg)
        c4, w4 = time.thread_time(), time.perf_counter()
        times = {
            "gmm_prior_update": (c1 - c0, w1 - w0),
            "dynamics_fit": (c3 - c2, w3 - w2),
            "eta_search": (c4 - c3, w4 - w3),
        }
        ti = alg.cur[0].traj_info
        kl_scale = 1 if eta_alg.traj_opt.cons_per_step else self.t
        result = {
            "gmm": gmm,
            "dynamics": dyn,
            "x0mu": ti.x0mu,
            "x0sigma": ti.x0sigma,
            "new_controller": new_ctrl,
            "eta": eta,
            "kl_step": eta_alg.base_kl_step * step_mult * kl_scale,
            "stats": stats,
        }
        return times, result

    def run_iteration(self, it):
        samples = self.samples(it)
        seed, given = self.cluster_init(it)
        prev_ctrl = self.prev_controller(it)
        if self.checked:
            # As our bench: the η search runs on the recorded dynamics, x0 and cost model.
            info = recorded_traj_info(self.g, it.out)
            cs = it.out["cost"].get("cs")
            cs = None if cs is None else arr(cs, "cost.cs")
        else:
            _, alg = self.fresh_state(it, samples)
            cc, cv, cm, cs = self.cost_model(it, samples, alg)
            dyn, x0mu, x0sigma = self.fit_only(it, samples, seed, given)
            info = traj_info(self.g, dyn, x0mu, x0sigma, cc, cv, cm)
        step_mult = self.step_mult(it, info, prev_ctrl, cs)
        _, ref = self.one_rep(it, samples, seed, given, info, prev_ctrl, step_mult, count=True)
        st = ref["stats"]
        res = {
            "iteration": it.index,
            "n": len(samples),
            "gmm_k": int(ref["gmm"].sigma.shape[0]),
            "em_iterations": st["estep_calls"],
            "backward_calls": len(st["backward"]),
            "eta_final": float(ref["eta"]),
            "kl_step": float(ref["kl_step"]),
            "step_mult": float(step_mult),
            "checks": self.check(it, seed, given, ref, step_mult) if self.checked else None,
        }
        self.done.append(
            {
                "gmm": ref["gmm"],
                "new_controller": ref["new_controller"],
                "info": info,
                "prev_controller": prev_ctrl,
                "cs": cs,
            }
        )
        if res["checks"] is not None and not res["checks"]["passed"]:
            return res
        per = {p: [] for p in PIECES + ("total",)}
        for _ in range(self.reps):
            times, _ = self.one_rep(it, samples, seed, given, info, prev_ctrl, step_mult)
            for p in PIECES:
                per[p].append(times[p])
            per["total"].append(tuple(sum(times[p][j] for p in PIECES) for j in (0, 1)))
        res["times"] = {
            p: {
                "cpu_ms": 1e3 * statistics.median(c for c, _ in v),
                "wall_ms": 1e3 * statistics.median(w for _, w in v),
            }
            for p, v in per.items()
        }
        return res

    def check(self, it, seed, given, ref, step_mult):
        """GPS's run against the recorded outputs."""
        out = it.out
        og = out["gmm"]
        st = ref["stats"]
        gmm = ref["gmm"]
        items = []

        def add(name, ok, detail):
            items.append({"name": name, "ok": bool(ok), "detail": detail})

        rec_idx = og.get("init_cluster_idx")
        if seed is not None and given is None and rec_idx is not None:
            state = np.random.get_state()
            np.random.seed(int(seed))
            drawn = np.random.randint(0, int(og["K"]), size=(1, len(rec_idx)))
            np.random.set_state(state)
            add(
                "init_cluster_idx from the seed",
                np.array_equal(drawn[0], np.asarray(rec_idx)),
                f"np.random.seed({seed}) draws the recorded assignment",
            )
        k = int(gmm.sigma.shape[0])
        add("clusters K", k == int(og["K"]), f"{k} vs recorded {og['K']}")
        n_ll = len(og["ll_trace"])
        add("EM iterations", st["estep_calls"] == n_ll, f"{st['estep_calls']} vs recorded {n_ll}")
        if k == int(og["K"]):
            e = max(
                rel_err(gmm.mu, og["mu"]),
                rel_err(gmm.sigma, og["sigma"]),
                rel_err(gmm.logmass, og["logmass"]),
            )
            add("GMM mu/sigma/logmass", e <= TOL_GMM, f"rel. err {e:.1e} (tol {TOL_GMM:.0e})")
        d = ref["dynamics"]
        od = out["dynamics"]
        e_f = max(rel_err(d.Fm, od["Fm"]), rel_err(d.fv, od["fv"]))
        e_c = rel_err(d.dyn_covar, od["dyn_covar"])
        add("dynamics Fm/fv", e_f <= TOL_DYN_FM, f"rel. err {e_f:.1e} (tol {TOL_DYN_FM:.0e})")
        add(
            "dynamics dyn_covar",
            e_c <= TOL_DYN_COVAR,
            f"rel. err {e_c:.1e} (tol {TOL_DYN_COVAR:.0e})",
        )
        e_x = max(rel_err(ref["x0mu"], out["x0mu"]), rel_err(ref["x0sigma"], out["x0sigma"]))
        add("x0mu/x0sigma", e_x <= TOL_X0, f"rel. err {e_x:.1e} (tol {TOL_X0:.0e})")
        sa = out.get("step_adjust")
        if sa is not None:
            e_s = rel_err([step_mult], [sa["step_mult_after"]])
            add(
                "step multiplier",
                e_s <= TOL_KL_STEP,
                f"{step_mult!r} vs recorded {sa['step_mult_after']!r}",
            )
        e_k = rel_err([ref["kl_step"]], [out["kl_step"]])
        add("KL target", e_k <= TOL_KL_STEP, f"{ref['kl_step']!r} vs recorded {out['kl_step']!r}")
        tr = out["dgd_trace"]
        bw = st["backward"]
        add("eta-search backward passes", len(bw) == len(tr), f"{len(bw)} vs recorded {len(tr)}")
        if len(bw) == len(tr):
            e_t = max(
                [0.0]
                + [
                    max(rel_err([a], [r["eta_in"]]), rel_err([b], [r["eta_out"]]))
                    for (a, b), r in zip(bw, tr)
                ]
            )
            add(
                "eta in/out of every backward pass",
                e_t <= TOL_ETA,
                f"rel. err {e_t:.1e} (tol {TOL_ETA:.0e})",
            )
        e_eta = rel_err([ref["eta"]], [out["eta_final"]])
        add("final eta", e_eta <= TOL_ETA, f"rel. err {e_eta:.1e} (tol {TOL_ETA:.0e})")
        nc, oc = ref["new_controller"], out["new_controller"]
        e_c = max(rel_err(nc.K, oc["K"]), rel_err(nc.k, oc["k"]))
        add(
            "new controller K/k",
            e_c <= TOL_CONTROLLER,
            f"rel. err {e_c:.1e} (tol {TOL_CONTROLLER:.0e})",
        )
        e_p = max(
            rel_err(nc.pol_covar, oc["pol_covar"]),
            rel_err(nc.chol_pol_covar, oc["chol_pol_covar"]),
            rel_err(nc.inv_pol_covar, oc["inv_pol_covar"]),
        )
        add(
            "new controller covariances",
            e_p <= TOL_CONTROLLER,
            f"rel. err {e_p:.1e} (tol {TOL_CONTROLLER:.0e})",
        )
        return {
            "passed": all(i["ok"] for i in items),
            "items": items,
            "eta_rel_err": e_eta,
            "controller_rel_err": e_c,
        }

    def run(self):
        """Every iteration in order; stops at the first that does not reproduce its record."""
        results = []
        for it in self.iterations:
            if it.inp is None:
                raise Refused(f"iterations[{it.index}] has no inputs")
            results.append(self.run_iteration(it))
            checks = results[-1]["checks"]
            if checks is not None and not checks["passed"]:
                break
        return results


# --- command line ------------------------------------------------------------------------


def one_blas_thread():
    """Checks (and if need be sets) one BLAS thread; returns the BLAS libraries' description,
    or None when threadpoolctl is not installed."""
    try:
        import threadpoolctl
    except ImportError:
        return None
    info = blas_info()
    if any(lib["num_threads"] != 1 for lib in info):
        threadpoolctl.threadpool_limits(limits=1, user_api="blas")  # process-wide, for good
        info = blas_info()
    if any(lib["num_threads"] != 1 for lib in info):
        raise SystemExit(f"error: BLAS runs on more than one thread: {info}")
    return info


def print_table(header, results, tol_line):
    print(header["title"])
    print(header["versions"])
    for r in results:
        print(f"iteration {r['iteration']} (N={r['n']}):")
        checks = r["checks"]
        if "times" not in r:
            print("  GPS did not reproduce the recorded outputs; no time reported:")
            for i in checks["items"]:
                if not i["ok"]:
                    print(f"    {i['name']}: {i['detail']}")
            continue
        gmm_note = f"(K={r['gmm_k']}, {r['em_iterations']} EM iterations"
        eta_note = f"({r['backward_calls']} backward passes"
        if checks is not None:
            it_out = header["recorded"][r["iteration"]]
            gmm_note += f"; recorded K={it_out['K']}, {it_out['em_iterations']}"
            eta_note += f"; recorded {it_out['backward_calls']}"
        notes = {"gmm_prior_update": gmm_note + ")", "eta_search": eta_note + ")"}
        print(f"{'piece':<22} {'wall ms':>9} {'cpu ms':>9}")
        for p in PIECES + ("total",):
            t = r["times"][p]
            print(
                f"{ROW_NAMES[p]:<22} {t['wall_ms']:>9.3f} {t['cpu_ms']:>9.3f}   {notes.get(p, '')}".rstrip()
            )
        if checks is not None:
            print(
                f"against the recorded outputs: final eta rel. err {checks['eta_rel_err']:.1e}, "
                f"new controller K/k max rel. err {checks['controller_rel_err']:.1e} ({tol_line}), "
                f"all {len(checks['items'])} checks passed: same work, same result"
            )
        else:
            print(
                f"inputs-only file: not checked (final eta {r['eta_final']!r}, KL target {r['kl_step']!r})"
            )


def main(argv=None):
    ap = argparse.ArgumentParser(
        description="Time GPS's own numpy pieces (GMM prior update, dynamics fit + x0, eta "
        "search) on the inputs of a GPS reference-vectors file, one BLAS thread, medians of "
        "thread CPU time; the rows match `learner bench --vectors FILE`."
    )
    ap.add_argument("file", help="vectors file (problem_*.json layout; `outputs` optional)")
    ap.add_argument(
        "--gps", required=True, help="GPS checkout (cbfinn/gps; the folder that holds python/gps)"
    )
    ap.add_argument(
        "--reps", type=int, default=21, help="timed repetitions per iteration (default 21)"
    )
    ap.add_argument(
        "--json", action="store_true", help="print one JSON object instead of the table"
    )
    args = ap.parse_args(argv)
    g = import_gps(os.path.abspath(args.gps))  # loads numpy's and scipy's BLAS
    blas = one_blas_thread()
    differing = gps_files_differing(args.gps)
    with open(args.file) as f:
        data = json.load(f)
    try:
        runner = Runner(g, data, max(1, args.reps))
        results = runner.run()
    except Refused as e:
        print(f"error: {args.file}: {e}", file=sys.stderr)
        return 2
    passed = all(r["checks"] is None or r["checks"]["passed"] for r in results)
    meta = data.get("meta") or {}
    report = {
        "file": args.file,
        "t": runner.t,
        "dx": runner.dx,
        "du": runner.du,
        "reps": max(1, args.reps),
        "checked": runner.checked,
        "reproduces_recorded_outputs": passed if runner.checked else None,
        "gps": {
            "path": os.path.abspath(args.gps),
            "files_not_of_" + GPS_COMMIT[:7]: differing,
            "file_recorded_with": meta.get("gps_commit"),
        },
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "blas": blas,
        "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
        "cpu": platform.processor() or platform.machine(),
        "loadavg": os.getloadavg(),
        "iterations": results,
    }
    if args.json:
        print(json.dumps(report))
    else:
        b = "not checked (no threadpoolctl)"
        if blas:
            b = ", ".join(
                f"{l['internal_api']} {l['version']} {l['architecture']} x{l['num_threads']}"
                for l in blas
            )
        code = (
            f"the files of {GPS_COMMIT[:7]}"
            if not differing
            else (f"WARNING: not the files of {GPS_COMMIT[:7]}: " + ", ".join(differing))
        )
        header = {
            "title": (
                f"bench_gps_numpy.py {args.file}: T={runner.t} dX={runner.dx} dU={runner.du}, "
                f"GPS's numpy code ({args.gps}: {code}) on the "
                f"{'recorded' if runner.checked else 'given'} inputs, {report['reps']} reps, medians, one thread"
            ),
            "versions": (
                f"Python {report['python']}, numpy {report['numpy']}, scipy {report['scipy']}; BLAS: {b}"
                + (
                    f"; OPENBLAS_CORETYPE={report['openblas_coretype']}"
                    if report["openblas_coretype"]
                    else ""
                )
            ),
            "recorded": [
                (
                    {
                        "K": it.out["gmm"]["K"],
                        "em_iterations": len(it.out["gmm"]["ll_trace"]),
                        "backward_calls": len(it.out["dgd_trace"]),
                    }
                    if it.out
                    else None
                )
                for it in runner.iterations
            ],
        }
        print_table(header, results, f"tol {TOL_CONTROLLER:.0e}; eta tol {TOL_ETA:.0e}")
    if not passed:
        print(
            f"error: {args.file}: GPS did not reproduce the recorded outputs (see above); no time reported",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
