"""What the benchmark scripts share: timing, the machine, reports, the data folder, options, and
the workloads and float64 peers that more than one script runs.

Every script in ``benchmarks/`` imports this module (``import _harness as h``; a script run as
``python benchmarks/NAME.py`` has ``benchmarks/`` on its path) and no other script.  From the
package they import only ``bsfjax``, ``bsfjax.internal``, ``bsfjax.experiments`` and
``bsfjax.plot``.  This module imports the standard library alone at import time (numpy, JAX and
bsfjax are imported where a helper needs them), so scripts that only drive the ``bsfjax``
command in child processes stay light.

* timing: :func:`timed` / :func:`median_time` (first call, then the median of ``repeats`` warm
  calls, each with ``jax.block_until_ready``) and :class:`PeakRSS` (peak resident memory over a
  block);
* the machine: :func:`machine_facts` (cores, memory, CPU model, Python / numpy / JAX versions,
  device, load) and the one-line descriptions the reports print;
* reports: :func:`write_text`, :func:`write_json`, :func:`write_csv`, atomic (a temporary file
  in the same folder, then ``os.replace``);
* data: :data:`DATA` (``../shared/data`` beside the repository) and :func:`require_data`, which
  ends the script with a message naming what is missing;
* options: :func:`parser` and the ``add_*`` helpers for the options most scripts have
  (``--out``, ``--data``, ``--repeats``, ``--cache``), :func:`int_list` / :func:`name_list`;
* workloads: :func:`random_regions`, :func:`cat_pair`, :func:`smpl_labels`,
  :data:`SEGMENTATION_PAIRS`;
* float64 peers: :func:`numpy_build`, :func:`numpy_transfer`, :func:`numpy_fps`,
  :func:`sk_omp`, :func:`sk_lasso`, :func:`rel_residual`, :func:`pyfm_mesh`.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import os
import platform
import sys
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

#: This folder, the repository root, and the shared data folder beside the repository.
BENCHMARKS = Path(__file__).resolve().parent
ROOT = BENCHMARKS.parent
DATA = ROOT.parent / "shared" / "data"
#: The SMPL part segmentation of the FAUST template (6890 vertices), in :data:`DATA`.
SMPL_SEGMENTATION = Path("segmentations") / "smpl_vert_segmentation.json"
#: Spectrum caches: the user's (kept between runs) and a temporary one.
HOME_CACHE = Path.home() / ".cache" / "bsfjax-spectra"
TMP_CACHE = Path("/tmp/bsfjax-spectra")
GIB = 2**30


# --- timing ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Timing:
    """One :func:`timed` measurement."""

    #: seconds of the first call (JAX compiles there)
    first: float
    #: seconds of each warm call after the first
    times: tuple[float, ...]
    #: the last call's result
    out: object

    @property
    def median(self) -> float:
        """Median seconds of the warm calls (the first call's when there were none)."""
        import numpy as np

        return float(np.median(self.times)) if self.times else self.first


def timed(fn, repeats: int, *, block: bool = True) -> Timing:
    """Call ``fn()`` once (the warm-up: it compiles), then ``repeats`` times, each call timed
    with ``time.perf_counter`` until ``jax.block_until_ready`` of its result (``block``)."""
    if block:
        import jax

        wait = jax.block_until_ready
    else:
        wait = lambda x: x  # noqa: E731
    t0 = time.perf_counter()
    out = wait(fn())
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = wait(fn())
        times.append(time.perf_counter() - t0)
    return Timing(first, tuple(times), out)


def median_time(fn, repeats: int) -> tuple[float, object]:
    """:func:`timed` in short: (median seconds of the ``repeats`` warm calls, last result)."""
    t = timed(fn, repeats)
    return t.median, t.out


class PeakRSS:
    """Peak resident set size of this process over a ``with`` block (sampled every 20 ms;
    needs ``psutil``)."""

    def __init__(self):
        import psutil

        self._proc = psutil.Process()
        self.peak = 0

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self._proc.memory_info().rss)
            self._stop.wait(0.02)

    def __enter__(self):
        self._stop = threading.Event()
        self.peak = self._proc.memory_info().rss
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._proc.memory_info().rss)


# --- the machine -----------------------------------------------------------------------------


def machine_facts(*, with_jax: bool = True) -> dict:
    """Facts about this machine for a report: CPU model, cores, memory, system, Python and
    (``with_jax``) numpy / JAX versions and the default device."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / GIB
    except (ValueError, OSError, AttributeError):
        memory = float("nan")
    facts = {
        "cpu_model": cpu, "processor": platform.processor() or platform.machine(),
        "arch": platform.machine(), "system": platform.system(),
        "platform": platform.platform(), "python": platform.python_version(),
        "cores": os.cpu_count(), "memory_gib": memory,
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"),
    }
    if with_jax:
        import jax
        import numpy as np

        facts.update(numpy=np.__version__, jax=jax.__version__, backend=jax.default_backend(),
                     device=str(jax.devices()[0]), device_platform=jax.devices()[0].platform,
                     device_count=jax.device_count())
    return facts


def describe_machine() -> str:
    """One line: CPU model, cores, memory, system, JAX and its devices, numpy."""
    m = machine_facts()
    return (f"{m['cpu_model']}, {m['cores']} cores, {m['memory_gib']:.0f} GiB RAM, "
            f"{m['system']}; jax {m['jax']} {m['backend']} ({m['device_count']} device(s)), "
            f"numpy {m['numpy']}")


def short_machine(*, device: bool = False) -> str:
    """``processor, N cores, system`` (and the default device's platform)."""
    m = machine_facts(with_jax=device)
    return (f"{m['processor']}, {m['cores']} cores, {m['system']}"
            + (f", {m['device_platform']}" if device else ""))


def cpus_note(*, load: bool = False, arch: bool = True) -> str:
    """``N CPUs`` (``, load average L``) (``, arch``): the tail of a timing sentence."""
    m = machine_facts(with_jax=False)
    return (f"{m['cores']} CPUs" + (f", load average {m['load_average']:.1f}" if load else "")
            + (f", {m['arch']}" if arch else ""))


# --- reports ---------------------------------------------------------------------------------


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically: a temporary file in the same folder (created if
    missing), then ``os.replace``; a reader never sees a partial report."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)  # mkstemp creates 0600: the permissions a plain open() gives
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8; a Markdown or JSON report) atomically."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path, obj, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON (a final newline) atomically."""
    return write_text(path, json.dumps(obj, indent=indent) + "\n")


def write_csv(rows, path) -> Path:
    """Write tidy rows (dicts; the union of their keys as the header, keys starting with ``_``
    left out) as CSV, atomically."""
    keys = [k for k in dict.fromkeys(k for r in rows for k in r) if not k.startswith("_")]
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=keys, extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    return write_text(path, buf.getvalue())


# --- the data folder -------------------------------------------------------------------------


def require_data(*paths, option: str | None = "--data") -> None:
    """End the script (status 1) with a message if any of ``paths`` (the data a benchmark
    reads) is missing; ``option`` names the option that points elsewhere."""
    missing = [str(p) for p in paths if not Path(p).exists()]
    if missing:
        where = f"; or point {option} at a copy" if option else ""
        raise SystemExit(
            f"{Path(sys.argv[0]).name}: not run, data missing: {', '.join(missing)}. The "
            f"benchmarks read the shared data folder ../shared/data beside the repository "
            f"({DATA}){where}.")


# --- options ---------------------------------------------------------------------------------


def parser(doc: str | None) -> argparse.ArgumentParser:
    """An argument parser described by the first line of the script's docstring."""
    return argparse.ArgumentParser(description=(doc or "").strip().splitlines()[0]
                                   if doc else None)


def add_out(ap, *, required: bool = True, default=None, type=str,
            help: str | None = "output folder") -> None:
    """``--out``: where the reports go (``required`` unless ``default`` is given)."""
    if default is not None:
        required = False
    ap.add_argument("--out", type=type, required=required, default=default, help=help)


def add_data(ap, sub: str = "", *, type=Path, help: str = "shared data folder") -> None:
    """``--data``: the data folder (default :data:`DATA`, or its ``sub`` folder)."""
    ap.add_argument("--data", type=type, default=type(DATA / sub) if sub else type(DATA),
                    help=f"{help} (default: %(default)s)")


def add_repeats(ap, default: int, help: str = "warm calls per timing (median)") -> None:
    """``--repeats``: the warm calls of each timing."""
    ap.add_argument("--repeats", type=int, default=default, help=help)


def add_cache(ap, default=HOME_CACHE, *, type=str,
              help: str = "spectrum cache folder (spectra are not timed)") -> None:
    """``--cache``: the spectrum cache folder."""
    ap.add_argument("--cache", type=type, default=None if default is None else type(default),
                    help=help)


def int_list(text: str) -> tuple[int, ...]:
    """``"10,30,50"`` → ``(10, 30, 50)``."""
    return tuple(int(x) for x in text.split(",") if x)


def pair_list(text: str) -> list[tuple[int, int]]:
    """``"0-10,1-11"`` → ``[(0, 10), (1, 11)]``: FAUST source-target registration numbers."""
    return [tuple(int(x) for x in p.split("-")) for p in text.split(",") if p]


def name_list(text: str) -> list[str]:
    """``"lstsq,omp"`` → ``["lstsq", "omp"]`` (empty items dropped)."""
    return [x for x in text.split(",") if x]


# --- workloads shared by several benchmarks --------------------------------------------------


#: The segmentation benchmark's nine pairs (six FAUST, three FAUST_5k), by registration number.
SEGMENTATION_PAIRS = {"faust": [("000", "001"), ("010", "012"), ("020", "022"), ("000", "010"),
                                ("001", "021"), ("012", "022")],
                      "faust_5k": [("000", "001"), ("000", "010"), ("001", "011")]}


def random_regions(mesh, mass, count, lo=0.05, hi=0.25, seed=0):
    """``(count, n)`` indicator functions of connected regions covering ``lo``–``hi`` of the area:
    vertices in breadth-first order from a random seed until the target area is reached."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order

    f = mesh.faces
    n = mesh.n_vertices
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    adj = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    adj = adj + adj.T
    rng = np.random.default_rng(seed)
    out = np.zeros((count, n))
    for r in range(count):
        order = breadth_first_order(adj, int(rng.integers(n)), directed=False,
                                    return_predecessors=False)
        target = rng.uniform(lo, hi) * mass.sum()
        take = order[: int(np.searchsorted(np.cumsum(mass[order]), target)) + 1]
        out[r, take] = 1.0
    return out


def cat_pair(data: Path, levels: int, decimate: int | None = None):
    """TOSCA ``cat0`` and ``cat6`` (on cat0's faces) Loop-subdivided ``levels`` times, then
    (``decimate``) both decimated to about that many vertices by the same edge collapses
    (``fast_simplification``); the identity map between them."""
    import numpy as np

    import bsfjax
    from bsfjax.internal import subdivide

    m0 = bsfjax.load_mesh(data / "tosca" / "cat" / "cat0.off")
    m6 = bsfjax.load_mesh(data / "tosca" / "cat" / "cat6.off")
    m6 = bsfjax.Mesh(m6.vertices, m0.faces, name="cat6 on cat0 faces")
    s0, s6 = subdivide(m0, "loop", levels), subdivide(m6, "loop", levels)
    if not decimate:
        return s0, s6
    import fast_simplification as fs

    faces = np.asarray(s0.faces, np.int32)
    target = 2 * int(decimate) + (faces.shape[0] - 2 * s0.n_vertices)  # Euler: F − 2V fixed
    _, _, collapses = fs.simplify(np.asarray(s0.vertices, np.float32), faces,
                                  target_count=target, return_collapses=True)
    out = []
    for m in (s0, s6):
        v, f, _ = fs.replay_simplification(np.asarray(m.vertices, np.float32), faces, collapses)
        out.append(bsfjax.Mesh(np.asarray(v, np.float64), np.asarray(f, np.int64),
                               name=f"{m.name} decimated"))
    return tuple(out)


def smpl_labels(data: Path = DATA):
    """The SMPL part of each of the FAUST template's 6890 vertices (parts in name order)."""
    import numpy as np

    seg = json.loads((Path(data) / SMPL_SEGMENTATION).read_text())
    lab = np.zeros(6890, np.int64)
    for i, (_, verts) in enumerate(sorted(seg.items())):
        lab[verts] = i
    return lab


# --- float64 peers ---------------------------------------------------------------------------

#: The paper's three scales and threshold.
TAUS = (1e-3, 5e-3, 1e-2)
GAMMA = 0.75


def numpy_build(spec, centers, taus=TAUS, gamma=GAMMA):
    """Algorithm 1 in float64 numpy, vectorized over centres (same steps as build_frame)."""
    import numpy as np

    area = spec.mass.sum()
    ghat = np.exp(-np.asarray(taus)[:, None] * area * (spec.evals - spec.evals[0]))  # (S, k)
    coeffs = (ghat[:, None, :] * spec.evecs[centers][None]).reshape(-1, spec.k).T  # (k, q)
    g = np.abs(spec.evecs @ coeffs)
    return g / g.max(axis=0) >= gamma, coeffs


def numpy_transfer(coeffs, C, evecs, gamma=GAMMA):
    """The frame transfer (Eq. 11–12) in float64 numpy."""
    import numpy as np

    g = np.abs(evecs[:, :C.shape[0]] @ (C @ coeffs[:C.shape[1]]))
    m = g.max(axis=0)
    return (g / np.where(m > 0, m, 1) >= gamma) & (m > 0)


def numpy_fps(points, first, n):
    """Euclidean farthest point sampling in a numpy loop (a running min-distance vector)."""
    import numpy as np

    idx = np.empty(n, dtype=np.int64)
    idx[0] = first
    mind = np.sum((points - points[first]) ** 2, axis=1)
    for i in range(1, n):
        idx[i] = np.argmax(mind)
        np.minimum(mind, np.sum((points - points[idx[i]]) ** 2, axis=1), out=mind)
    return idx


def normalized(B):
    """The non-zero columns of ``B`` normalised, their norms, and which columns they are."""
    import numpy as np

    norms = np.linalg.norm(B, axis=0)
    ok = norms > 0
    return B[:, ok] / norms[ok], norms, ok


def back(beta, norms, ok, q):
    """Coefficients of the normalised columns back to the ``q`` columns of ``B``."""
    import numpy as np

    alpha = np.zeros((q,) + beta.shape[1:])
    alpha[ok] = beta / norms[ok].reshape((-1,) + (1,) * (beta.ndim - 1))
    return alpha


def sk_omp(B, F, S, precompute):
    """scikit-learn ``orthogonal_mp`` with ``S`` atoms on the normalised columns of ``B``."""
    from sklearn.linear_model import orthogonal_mp

    D, norms, ok = normalized(B)
    beta = orthogonal_mp(D, F.T, n_nonzero_coefs=S, precompute=precompute)
    return back(beta, norms, ok, B.shape[1]).T


#: Facts about the peers' runs (e.g. how many Lasso fits did not converge), for the reports.
PEER_NOTES: dict[str, object] = {}


def sk_lasso(B, F, lam):
    """scikit-learn ``Lasso(alpha=λ_i / n)`` per function, ``λ_i = lam · max|Bᵀf_i|``."""
    import numpy as np
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import Lasso

    n = B.shape[0]
    out = []
    not_converged = 0
    for f in F:
        l_abs = lam * np.abs(B.T @ f).max()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            out.append(Lasso(alpha=l_abs / n, fit_intercept=False).fit(B, f).coef_)
        not_converged += any(issubclass(w.category, ConvergenceWarning) for w in caught)
    PEER_NOTES["sklearn Lasso fits not converged (default tol=1e-4, max_iter=1000)"] = (
        not_converged)
    return np.stack(out)


def rel_residual(B, F, A):
    """``‖f_i − B α_i‖ / ‖f_i‖`` per function."""
    import numpy as np

    return np.linalg.norm(F - A @ B.T, axis=1) / np.linalg.norm(F, axis=1)


def pyfm_mesh(mesh, spec, W):
    """A pyFM ``TriMesh`` holding bsfjax's stiffness ``W``, mass and eigenpairs (pyFM's
    ``preprocess`` then only truncates them)."""
    import numpy as np
    import scipy.sparse as sp
    from pyFM.mesh import TriMesh

    tm = TriMesh(np.array(mesh.vertices), np.array(mesh.faces))
    tm.stiffness = W
    tm.mass = sp.diags(spec.mass).tocsc()
    tm.eigenvalues = spec.evals.copy()
    tm.eigenvectors = spec.evecs.copy()
    return tm


# --- scan-like targets (the scan benchmarks: bench_scans*.py, bench_point_clouds.py) ---------


#: The landmark vertices of the tests and docs (the same on every registration).
LANDMARKS = (412, 3216, 5907, 6296, 2445)


def accuracy(labels, truth, mass) -> float:
    import numpy as np

    return float(np.sum(mass * (labels == truth)) / np.sum(mass))


def run_cli(source: str, target: str, labels: str, out: str, landmarks: bool, denoise: bool,
            extra=()):
    """``bsfjax transfer`` in this process: the labels written, the stderr text.  ``landmarks``:
    ``True`` (the 5 pairs ``LANDMARKS``), ``False`` (none) or ``(source rows, target rows)``;
    ``extra``: more arguments (``--map p2p FILE``, ``--method ...``)."""
    import numpy as np

    from bsfjax.cli import main

    argv = ["transfer", source, target, "--labels", labels, "--out", out, *extra]
    if landmarks:
        src, tgt = (LANDMARKS, LANDMARKS) if landmarks is True else landmarks
        argv += ["--landmarks", f"{','.join(map(str, src))}:{','.join(map(str, tgt))}"]
    if not denoise:
        argv.append("--no-denoise")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(argv)
    if rc:
        raise RuntimeError(f"bsfjax transfer failed ({rc}): {err.getvalue()}")
    return np.loadtxt(out, dtype=np.int64), err.getvalue()


def run_pyfm(source, target, truth, mass, landmarks=None, target_truth=None) -> float:
    """pyFM's own pipeline (its README's: WKS with the 5 landmarks, a 35 × 35 map, ZoomOut
    15 steps on 2000 samples) from ``source`` to ``target``: the accuracy of the pulled-back
    labels.  ``landmarks``: ``(source rows, target rows)`` instead of ``LANDMARKS`` on both;
    ``target_truth``: the target's labels when its vertices are not the source's (``truth``:
    the source's)."""
    import numpy as np
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    model = FunctionalMapping(*[TriMesh(np.array(m.vertices), np.array(m.faces))
                                for m in (source, target)])
    lm = np.stack(landmarks or [LANDMARKS, LANDMARKS], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.preprocess(n_descr=100, descr_type="WKS", landmarks=lm, subsample_step=5,
                         k_process=200, verbose=False)
        model.fit(K=(35, 35), w_descr=1e0, w_lap=1e-2, w_dcomm=1e-1, w_orient=0)
        model.zoomout_refine(nit=15, step=1, subsample=2000, verbose=False)
    return accuracy(truth[model.get_p2p()], truth if target_truth is None else target_truth,
                    mass)


# --- ceilings (bench_scans_partial_ceiling.py, bench_cloud_ceiling.py) ------------------------


def ceiling_table(rows, clean: str) -> str:
    """Markdown of a ceiling benchmark's rows (``pair``, ``target`` and one accuracy per way):
    each value with its Δ in points from the first way's value on the pair's ``clean``
    target; a way a row did not run is an empty cell."""
    names = list(dict.fromkeys(c for r in rows for c in r if c not in ("pair", "target")))
    lines = ["| pair | target | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    ref = {r["pair"]: r[names[0]] for r in rows if r["target"] == clean}
    for r in rows:
        cells = []
        for c in names:
            if c not in r:
                cells.append("")
                continue
            d = ("" if r["target"] == clean or r["pair"] not in ref else
                 f" ({100 * (r[c] - ref[r['pair']]):+.1f})")
            cells.append(f"{100 * r[c]:.1f} %{d}")
        lines.append(f"| {r['pair']} | {r['target']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def ceiling_main(doc: str, run, clean: str, note: str, seed: bool = False) -> None:
    """A ceiling benchmark's command line: ``--out`` (Markdown, and its rows as JSON
    beside it), ``--data``, ``--pairs`` and, with ``seed``, ``--seed``; ``run(data, folder,
    pairs)`` (``run(data, folder, pairs, seed)``) gives the rows."""
    ap = parser(doc)
    add_out(ap, help="output Markdown file (a .json of the rows beside it)")
    add_data(ap)
    ap.add_argument("--pairs", default="0-10,1-11,2-12",
                    help="source-target registration numbers (default 0-10,1-11,2-12)")
    if seed:
        ap.add_argument("--seed", type=int, default=0,
                        help="the target's draw (default 0; the suite's draw D takes 2D, 2D + 1)")
    args = ap.parse_args()
    require_data(Path(args.data) / "faust", Path(args.data) / SMPL_SEGMENTATION)
    with tempfile.TemporaryDirectory() as tmp:
        rest = (args.seed,) if seed else ()
        rows = run(Path(args.data), Path(tmp), pair_list(args.pairs), *rest)
    text = ceiling_table(rows, clean) + f"\n{short_machine()}; {note}\n"
    print(text)
    write_text(args.out, text)
    write_json(Path(args.out).with_suffix(".json"), {"rows": rows})
