"""Reading a squeal results file (docs/user-guide.md, "Results file").

    from squeal.results import open_results
    with open_results("run.h5") as r:
        r.status                      # root attribute, decoded: "complete", "interrupted (SIGINT) ...", ...
        r.model["mu"]                 # /model attributes
        r.stability.unstable_period() # 2 pi / omega of the most unstable mode (None: none unstable)
        r.transient["U"]              # any dataset, read whole as a numpy array
        r.transient.attrs["trend"]    # attributes, strings decoded once

Each analysis group is a `Group` (None when the file has none): `g[name]` reads a dataset (or
returns a sub-`Group`), `g.attrs` holds the decoded attributes, `g.dataset(name)` the h5py dataset
for partial reads. The typed groups add accessors for what the scripts and the tests use.
`require` and `open_results` stop the program with a one-line message naming what is missing and
the analysis that writes it; the plotting commands rely on that.
"""
import math
import os
import sys

try:
    import h5py
except ImportError:  # pragma: no cover
    sys.exit("squeal scripts: error: the h5py module is required (apt-get install python3-h5py)")
import numpy as np

PROG = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "squeal"


def fail(msg):
    print(f"{PROG}: error: {msg}", file=sys.stderr)
    sys.exit(1)


def decode(v):
    """bytes -> str; a one-element array or numpy scalar -> its Python value; anything else as is."""
    if isinstance(v, (bytes, np.bytes_)):
        return v.decode()
    if isinstance(v, np.ndarray) and v.size == 1 and v.ndim <= 1 and v.dtype.kind in "SOU":
        return decode(v.reshape(-1)[0])
    if isinstance(v, np.generic):
        return v.item()
    return v


def decoded_attrs(obj):
    return {k: decode(v) for k, v in obj.attrs.items()}


class Group:
    """One group of a results file: datasets read on access, attributes decoded once."""

    def __init__(self, h5group):
        self.h5 = h5group
        self.attrs = decoded_attrs(h5group)

    @property
    def name(self):
        return self.h5.name

    def __contains__(self, key):
        return key in self.h5

    def __getitem__(self, key):
        obj = self.h5[key]
        return Group(obj) if isinstance(obj, h5py.Group) else obj[()]

    def get(self, key, default=None):
        return self[key] if key in self.h5 else default

    def keys(self):
        return list(self.h5.keys())

    def dataset(self, key):
        return self.h5[key]

    def array(self, key, dtype=float):
        return np.asarray(self.h5[key][()], dtype=dtype)


class Stability(Group):
    @property
    def eigenvalues(self):
        """k x 2 (sigma, omega); (0, 2) when empty."""
        ev = self.array("eigenvalues")
        return ev.reshape(0, 2) if ev.size == 0 else ev

    @property
    def unstable(self):
        """Row indices of the unstable modes in the band, most unstable first."""
        return np.asarray(self.h5["unstable"][()]).ravel().astype(int) if "unstable" in self.h5 else np.array([], int)

    @property
    def frequency(self):
        return self.array("frequency")

    def unstable_period(self):
        """2 pi / omega of the most unstable mode, None when none is unstable."""
        un = self.unstable
        if un.size == 0:
            return None
        return 2 * math.pi / self.eigenvalues[un[0], 1]

    def mode(self, m):
        """phi of eigenvalue m (column m of /stability/modes), complex."""
        return self.h5["modes/re"][:, m] + 1j * self.h5["modes/im"][:, m]

    def verdict(self):
        """The run's three-way verdict (docs/user-guide.md, Band-complete stability) in words."""
        a = self.attrs
        fmin = a.get("fmin", 0)
        band = f"{fmin:g}-{a.get('fmax', 0):g} Hz"
        un, ev = self.unstable, self.eigenvalues
        below = int(np.count_nonzero((ev[:, 0] > 0) & (ev[:, 1] / (2 * math.pi) < fmin)))
        below = f"; {below} unstable mode(s) below fmin, not reported" if below else ""
        fmax = a.get("fmax", 0)
        above = int(np.count_nonzero((ev[:, 0] > 0) & (ev[:, 1] / (2 * math.pi) > fmax))) if fmax > 0 else 0
        below += f"; {above} unstable mode(s) above fmax, not reported" if above else ""
        if un.size:
            s, w = ev[un[0]]
            return (f"UNSTABLE: {un.size} unstable mode(s){f' above fmin = {fmin:g} Hz' if fmin > 0 else ''}; most "
                    f"unstable {w / (2 * math.pi):.6g} Hz, sigma = {s:.6g} 1/s{below}")
        if a.get("band_covered", 0) or a.get("all_eigenvalues", 0):
            return f"stable in the band {band}{below}"
        return (f"stability undecided: {self.eigenvalues.shape[0]} eigenvalue(s) computed, "
                f"complete up to {a.get('complete_up_to', float('nan')):g} Hz")


class Sweep(Group):
    def _attr_array(self, name, n):
        """Attribute `name` as a float array of length n (NaN when absent)."""
        if name not in self.attrs:
            return np.full(n, np.nan)
        a = np.atleast_1d(np.asarray(self.attrs[name], dtype=float)).ravel()
        if a.size == 1 and n > 1:
            a = np.full(n, a[0])
        if a.size != n:
            out = np.full(n, np.nan)
            out[: min(n, a.size)] = a[: min(n, a.size)]
            return out
        return a

    @property
    def V(self):
        return self.array("V").ravel() if "V" in self.h5 else None

    @property
    def critical_mu(self):
        c = self.attrs.get("critical_mu")
        return None if c is None else np.atleast_1d(np.asarray(c, dtype=float))

    def runs(self, path=""):
        """One dict per sliding speed: mu, V, V_units, sigma and omega (n_mu x k, NaN where the
        point failed), failed, mu_c, f_c. Stops the program on a malformed group."""
        mu = self.array("mu").ravel()
        ev = self.array("eigenvalues")
        if ev.ndim == 3:  # single V written without the leading axis
            ev = ev[np.newaxis]
        if ev.ndim != 4 or ev.shape[-1] != 2 or ev.shape[1] != mu.size:
            fail(f"'{path}': /sweep/eigenvalues has shape {ev.shape}, expected (n_V, {mu.size}, k, 2)")
        n_v = ev.shape[0]
        if "V" in self.h5:
            V = self.V
            v_units = decode(self.h5["V"].attrs.get("units", b"m/s"))
        else:
            V, v_units = np.full(n_v, np.nan), "m/s"
        if V.size != n_v:
            fail(f"'{path}': /sweep/V has {V.size} value(s) but eigenvalues hold {n_v}")
        failed = np.zeros((n_v, mu.size), dtype=bool)
        if "failed" in self.h5:
            failed = np.asarray(self.h5["failed"][()]).reshape(n_v, mu.size) != 0
        mu_c = self._attr_array("critical_mu", n_v)
        f_c = self._attr_array("coalescence_frequency", n_v)
        runs = []
        for i in range(n_v):
            e = ev[i].copy()
            e[failed[i]] = np.nan
            runs.append(dict(path=path, mu=mu, V=V[i], V_units=v_units, sigma=e[..., 0],
                             omega=e[..., 1], failed=failed[i], mu_c=mu_c[i], f_c=f_c[i]))
        return runs


class Shooting(Group):
    @property
    def converged(self):
        return int(self.attrs.get("converged", 0))

    @property
    def period(self):
        return float(self.h5["period"][()])

    @property
    def iterations(self):
        return int(self.h5["iterations"][()]) if "iterations" in self.h5 else -1

    @property
    def trivial(self):
        return int(self.attrs["trivial_multiplier_index"])

    @property
    def floquet(self):
        """m x 2 (Re, Im) multipliers."""
        return self.h5["floquet"][()]


class Transient(Group):
    @property
    def complete(self):
        return int(self.attrs.get("complete", 1))

    @property
    def period(self):
        return self.attrs.get("period")


class Continuation(Group):
    @property
    def parameter(self):
        return self.attrs.get("parameter", "mu")

    def events(self):
        """(type, parameter value) of each event of the branch."""
        if "events" not in self.h5 or "param" not in self.h5["events"]:
            return []
        types = [t for t in decode(self.h5["events"].attrs.get("types", b"")).split(",") if t]
        return [(t, float(p)) for t, p in zip(types, np.asarray(self.h5["events/param"][()]))]


GROUP_TYPES = {"stability": Stability, "sweep": Sweep, "shooting": Shooting, "transient": Transient,
               "continuation": Continuation}


class Results:
    """An open results file. Use as a context manager, or call close()."""

    def __init__(self, path, mode="r"):
        self.path = path
        self.h5 = h5py.File(path, mode)
        self.attrs = decoded_attrs(self.h5)
        self._groups = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.h5.close()

    def __contains__(self, key):
        return key in self.h5

    @property
    def status(self):
        return str(self.attrs.get("status", ""))

    @property
    def creator(self):
        return str(self.attrs.get("creator", ""))

    @property
    def groups(self):
        return [k for k in self.h5 if isinstance(self.h5[k], h5py.Group)]

    @property
    def model(self):
        """/model's attributes (name, dofs, contact_points, mu, V, friction); {} without /model."""
        return decoded_attrs(self.h5["model"]) if "model" in self.h5 else {}

    def group(self, name):
        """The group `name` (typed where a type exists), None when the file has none."""
        if name not in self._groups:
            obj = self.h5.get(name)
            self._groups[name] = GROUP_TYPES.get(name, Group)(obj) if isinstance(obj, h5py.Group) else None
        return self._groups[name]

    def require(self, name, datasets=(), analysis=None):
        """The group `name`; stops the program with a message when it or one of `datasets` is missing."""
        g = self.group(name)
        if g is None:
            fail(f"'{self.path}' has no /{name} group (run squeal with -analyses {analysis or name})")
        for d in datasets:
            if d not in g:
                fail(f"'{self.path}': /{name}/{d} is missing")
        return g

    def walk(self):
        """(path, raw attributes, data) of the root and of every group and dataset below it, in
        h5py's visiting order; data is the dataset read whole, None for a group."""
        yield "/", dict(self.h5.attrs.items()), None
        items = []
        self.h5.visititems(lambda name, obj: items.append((name, obj)))
        for name, obj in items:
            yield name, dict(obj.attrs.items()), obj[()] if isinstance(obj, h5py.Dataset) else None

    equilibrium = property(lambda self: self.group("equilibrium"))
    stability = property(lambda self: self.group("stability"))
    sweep = property(lambda self: self.group("sweep"))
    energy = property(lambda self: self.group("energy"))
    shooting = property(lambda self: self.group("shooting"))
    transient = property(lambda self: self.group("transient"))
    continuation = property(lambda self: self.group("continuation"))
    mesh = property(lambda self: self.group("mesh"))
    steady_state = property(lambda self: self.group("steady_state"))


def open_results(path, mode="r"):
    """Results(path), or stop the program with a message when the file is missing or not HDF5."""
    if not os.path.isfile(path):
        fail(f"results file '{path}' not found")
    try:
        return Results(path, mode)
    except OSError as e:
        fail(f"cannot open '{path}' as HDF5: {e}")


def status_of(path):
    """The root status attribute of the results file at `path`, decoded."""
    with Results(path) as r:
        return r.status
