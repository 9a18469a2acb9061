"""meshdeco: sparse, localized deformation components from collections of meshes that share one
connectivity (SPLOCS, region PCA, PCA and a mesh-convolutional autoencoder), with NumPy arrays
in and out. This package calls the Rust library directly (``meshdeco._native``); it never runs
the ``meshdeco`` command.

Conventions (every function):

- positions are ``float64`` in the data's own units: one mesh ``(N, 3)``, frames ``(F, N, 3)``;
- triangles (``faces``) are integer ``(T, 3)``, 0-based vertex indices, counter-clockwise seen
  from outside; they are returned as ``int64``;
- weights are ``float64`` ``(F, K)`` (one row per frame, K = ``Model.n_components``) in the
  model's own coordinates (linear models: component weights; region PCA: the concatenated
  per-region coefficients; the autoencoder: its latent code).

Arrays of another float or integer dtype, Fortran order or with strides are converted (copied)
once; other dtypes, wrong shapes and non-finite values raise :class:`ArgumentError` /
:class:`ArgumentTypeError` naming the argument. Every error is a :class:`Error`; long calls
release the GIL. See docs/python.md in the repository.
"""

from __future__ import annotations

import json
import os
import sys
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence, Union

import numpy as np

from . import _errors, _native
from ._errors import (
    ArgumentError,
    ArgumentTypeError,
    ConfigError,
    Error,
    FileError,
    FileNotFound,
    InvalidInput,
    NumericalError,
    ParseError,
)

__version__: str = _native.__version__

PathLike = Union[str, "os.PathLike[str]"]
ProgressCallback = Callable[[str, int, int, str], None]

__all__ = [
    *_errors.__all__,
    "Model",
    "Pose",
    "View",
    "load_mesh",
    "load_sequence",
    "save_mesh",
    "train",
    "load_model",
]


# ------------------------------------------------------------------------------------------
# Argument checks (dtype and shape here; finiteness and index ranges in the library)


def _array(name: str, x: Any) -> np.ndarray:
    if x is None:
        raise ArgumentTypeError(f"{name}: is None; an array is required")
    try:
        return np.asarray(x)
    except Exception as e:  # ragged lists and the like
        raise ArgumentTypeError(f"{name}: cannot be read as an array ({e})") from None


def _floats(name: str, x: Any, shape: Sequence[Optional[int]], expected: str) -> np.ndarray:
    a = _array(name, x)
    if a.dtype.kind not in "fiu":
        raise ArgumentTypeError(f"{name}: dtype {a.dtype} is not a real number type (float64 expected)")
    if a.ndim != len(shape) or any(w is not None and s != w for s, w in zip(a.shape, shape)):
        raise ArgumentError(f"{name}: shape {a.shape}; expected {expected}")
    if a.size == 0:
        raise ArgumentError(f"{name}: shape {a.shape} is empty; expected {expected}")
    return np.ascontiguousarray(a, dtype=np.float64)


def _faces(name: str, x: Any) -> np.ndarray:
    a = _array(name, x)
    if a.dtype.kind not in "iu":
        raise ArgumentTypeError(f"{name}: dtype {a.dtype}; triangle indices must be integers (int64 expected)")
    if a.ndim != 2 or a.shape[1] != 3:
        raise ArgumentError(f"{name}: shape {a.shape}; expected (T, 3) vertex indices")
    if a.dtype.kind == "u" and a.size and int(a.max()) > np.iinfo(np.int64).max:
        raise ArgumentError(f"{name}: index {int(a.max())} does not fit in int64")
    return np.ascontiguousarray(a, dtype=np.int64)


def _path(name: str, x: Any) -> str:
    try:
        return os.fspath(x)
    except TypeError:
        raise ArgumentTypeError(f"{name}: {type(x).__name__} is not a path (str or os.PathLike)") from None


# ------------------------------------------------------------------------------------------
# Meshes


def load_mesh(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Reads one mesh file (OBJ, PLY or OFF; polygons are fanned into triangles).

    Returns ``(vertices, faces)``: ``float64 (N, 3)`` positions in the file's units and
    ``int64 (T, 3)`` 0-based triangles. Raises :class:`FileNotFound` for a missing file and
    :class:`ParseError` (naming the file and line) for a malformed one.
    """
    return _native.load_mesh(_path("path", path))


def load_sequence(path: PathLike, *, return_names: bool = False) -> Any:
    """Reads frames that share one connectivity: a directory or glob of mesh files (natural
    order: ``2.obj`` before ``10.obj``), an HDF5 file with its triangles in ``tris``
    (``"x.h5"`` reads the dataset ``verts``, ``"x.h5:name"`` another; F × N × 3 or N × 3 × F)
    or a built-in synthetic set (``"synthetic:tube"``, ``"synthetic:bumps"``,
    ``"synthetic:pieces"``).

    Returns ``(frames, faces)``: ``float64 (F, N, 3)`` and ``int64 (T, 3)``; with
    ``return_names=True`` also the frame names (file stems), ``(frames, faces, names)``.
    A frame whose vertex count or triangles differ from the first is a :class:`ParseError`
    naming the file.
    """
    frames, faces, names = _native.load_sequence(_path("path", path))
    return (frames, faces, names) if return_names else (frames, faces)


def save_mesh(path: PathLike, vertices: Any, faces: Any) -> None:
    """Writes one mesh; the format follows the extension (``.obj``, ``.ply``, ``.off``).

    ``vertices``: ``(N, 3)`` positions (finite); ``faces``: integer ``(T, 3)`` 0-based indices
    below N. The file is written atomically.
    """
    p = _path("path", path)
    v = _floats("vertices", vertices, (None, 3), "(N, 3) positions")
    f = _faces("faces", faces)
    _native.save_mesh(p, v, f)


# ------------------------------------------------------------------------------------------
# Models


class Pose(NamedTuple):
    """The result of :meth:`Model.pose`."""

    positions: np.ndarray
    """Posed positions, ``float64 (N, 3)``, data units."""
    weights: np.ndarray
    """The posed weights (model coordinates), ``float64 (K,)``."""
    start: np.ndarray
    """The start shape, ``float64 (N, 3)``, data units."""


class View:
    """A model's standalone viewer page (:meth:`Model.show`, :meth:`Model.html`): one
    self-contained HTML document — sliders, heat maps, the training frames — that needs no server
    and makes no network request. In Jupyter (JupyterLab, classic Notebook, VS Code) it displays
    inline as an ``<iframe srcdoc=…>`` (``_repr_html_``); :meth:`save` writes the page to a file.
    """

    __slots__ = ("html", "height")

    def __init__(self, html: str, height: int = 640) -> None:
        self.html = html
        """The page (HTML text)."""
        self.height = height
        """Height of the inline frame, CSS pixels."""

    def _repr_html_(self) -> str:
        import html as _html

        return (
            f'<iframe srcdoc="{_html.escape(self.html, quote=True)}" '
            f'style="width: 100%; height: {int(self.height)}px; border: 0;" '
            'title="meshdeco standalone viewer"></iframe>'
        )

    def save(self, path: PathLike) -> None:
        """Writes the page to ``path`` (an ``.html`` file that opens from disk)."""
        p = _path("path", path)
        with open(p, "w", encoding="utf-8") as f:
            f.write(self.html)

    def __repr__(self) -> str:
        return f"<meshdeco.View: standalone page of {len(self.html)} characters>"


class Model:
    """A trained meshdeco model (any method): returned by :func:`train` and :func:`load_model`.

    Positions are in the data's own units (the unit-box scaling of ``data.unit_box`` is applied
    and undone inside); weights are the model's own coordinates.
    """

    __slots__ = ("_m",)

    def __init__(self, native: Any) -> None:
        self._m = native

    def __repr__(self) -> str:
        where = f", directory={self.directory!r}" if self.directory else ""
        return f"<meshdeco.Model kind={self.kind!r} representation={self.representation!r} K={self.n_components} N={self.n_vertices}{where}>"

    @property
    def kind(self) -> str:
        """The method: ``"pca"``, ``"splocs"``, ``"region-pca"`` or ``"autoencoder"``."""
        return self._m.kind

    @property
    def representation(self) -> str:
        """The representation the method ran on (``"displacement"``, ``"triangle-gradient"``, ``"acap"``)."""
        return self._m.representation

    @property
    def n_components(self) -> int:
        """K: the number of weights of a shape (region PCA: the total over regions)."""
        return self._m.n_components

    @property
    def n_vertices(self) -> int:
        """N: vertices of the rest mesh (and of every shape the model encodes or decodes)."""
        return self._m.n_vertices

    @property
    def rest(self) -> np.ndarray:
        """The rest shape, ``float64 (N, 3)``, data units."""
        return self._m.rest

    @property
    def faces(self) -> np.ndarray:
        """The triangles shared by every shape, ``int64 (T, 3)``."""
        return self._m.faces

    @property
    def train_frames(self) -> list[str]:
        """Names of the training frames."""
        return self._m.train_frames

    @property
    def train_weights(self) -> Optional[np.ndarray]:
        """Weights of the training frames as stored at training, ``float64 (F, K)`` (``None``
        when the model does not store them)."""
        return self._m.train_weights

    @property
    def metrics(self) -> Optional[dict[str, Any]]:
        """The training's ``metrics.json`` as a dict (``train_erms``, ``test_erms``, …; Erms in
        data units), or ``None`` when unknown."""
        text = self._m.metrics_json
        return None if text is None else json.loads(text)

    @property
    def directory(self) -> Optional[str]:
        """The artefact directory (``None`` when trained without ``out``)."""
        return self._m.directory

    def components(self) -> list[dict[str, Any]]:
        """The components in index order, each a dict: ``index`` (position in the weight
        vector), ``rank`` (0 = first shown), ``name`` (``k03``, ``r02_c01``, ``0_12``),
        ``centre`` (vertex of largest magnitude) and ``magnitude`` (``float64 (N,)`` ≥ 0: the
        per-vertex heat map)."""
        return self._m.components()

    def encode(self, frames: Any) -> np.ndarray:
        """The model's own encoding of shapes into weights.

        ``frames``: ``(F, N, 3)`` positions in data units (or one shape ``(N, 3)``), N the
        model's vertex count. Returns ``float64 (F, K)`` (one shape: ``(K,)``).
        """
        a = _array("frames", frames)
        if a.ndim == 2:
            return self.encode(a[None])[0]
        f = _floats("frames", a, (None, self.n_vertices, 3), f"(F, {self.n_vertices}, 3) or ({self.n_vertices}, 3)")
        return self._m.encode(f)

    def decode(self, weights: Any) -> np.ndarray:
        """Positions of weight vectors, batched in the library (no per-frame Python work).

        ``weights``: ``(F, K)`` (or one vector ``(K,)``), finite. Returns ``float64 (F, N, 3)``
        (one vector: ``(N, 3)``) in data units.
        """
        a = _array("weights", weights)
        if a.ndim == 1:
            return self.decode(a[None])[0]
        w = _floats("weights", a, (None, self.n_components), f"(F, {self.n_components}) or ({self.n_components},)")
        return self._m.decode(w)

    def synthesize(self, dials: Any) -> np.ndarray:
        """The shape of synthesis dials (``meshdeco synthesize --weights``): ``(K,)`` numbers,
        equal to the weights for linear and region models; for the autoencoder dial i maps to
        ``z_i = Z_r,i + (Z_h,i − Z_r,i)·dial_i`` (0: rest, 1: the component's extreme shape).
        Returns ``float64 (N, 3)``, data units."""
        d = _floats("dials", dials, (self.n_components,), f"({self.n_components},)")
        return self._m.synthesize(d)

    def pose(
        self,
        targets: Mapping[int, Any],
        start: Any = None,
        *,
        gamma: Optional[float] = None,
        beta: Optional[float] = None,
        max_iterations: Optional[int] = None,
        prior: Optional[str] = None,
        spread: Optional[float] = None,
    ) -> Pose:
        """Poses the model: moves constrained vertices to targets, the rest following the model.

        ``targets``: ``{vertex: (x, y, z)}``, 0-based vertex indices (distinct, below N) to
        target positions in data units (finite). ``start``: ``None`` (the model's default start,
        e.g. the rest shape) or a shape ``(N, 3)`` in data units whose encoding is the start.

        Options (``None``: the model kind's default, :func:`meshdeco pose`'s): ``gamma`` ≥ 0,
        dimensionless pull towards the start, as strong wherever the pins are (default: PCA and
        SPLOCS 5, region PCA 0.03, the autoencoder 1); ``beta`` ≥ 0, boundary consistency
        between regions (region PCA; default 1e-3); ``max_iterations`` 1..1000, Gauss–Newton
        iterations (autoencoder; default 30); ``prior``: ``"shape"`` (the pull measures the
        shape's change), ``"weights"`` (the papers' ‖w − w0‖²; region PCA's and the
        autoencoder's default) or ``"data"`` (the weights measured by the training weights'
        spread; PCA's and SPLOCS's default); ``spread`` 0..1, the
        landing correction's radius as a fraction of the bounding-box diagonal (default 0.2; 0:
        the model's own shape): what the model's shape leaves between a pin and its target is
        added as a smooth displacement that fades to zero that far along the surface, so every
        pin lands (``weights`` stay the model's). A model reads only the options of
        :meth:`pose_parameters` (and every model reads ``spread``).

        Returns :class:`Pose` ``(positions (N, 3), weights (K,), start (N, 3))``, data units.
        """
        if not isinstance(targets, Mapping):
            raise ArgumentTypeError(f"targets: {type(targets).__name__}; expected a dict {{vertex: (x, y, z)}}")
        if len(targets) == 0:
            raise ArgumentError("targets: empty; give at least one {vertex: (x, y, z)}")
        obj: dict[str, list[float]] = {}
        for v, t in targets.items():
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
                raise ArgumentTypeError(f"targets: key {v!r} is not a vertex index (int)")
            p = _floats(f"targets[{int(v)}]", t, (3,), "(3,) a target position")
            if not np.all(np.isfinite(p)):
                raise ArgumentError(f"targets[{int(v)}]: {p.tolist()} is not finite")
            obj[str(int(v))] = p.tolist()
        s = None
        if start is not None:
            s = _floats("start", start, (self.n_vertices, 3), f"({self.n_vertices}, 3)")
        for name, value in (("gamma", gamma), ("beta", beta), ("spread", spread)):
            if value is not None and not isinstance(value, (int, float, np.floating, np.integer)):
                raise ArgumentTypeError(f"{name}: {type(value).__name__} is not a number")
        if max_iterations is not None and (
            isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 0
        ):
            raise ArgumentError(f"max_iterations: {max_iterations!r} is not a positive integer")
        if prior is not None and not isinstance(prior, str):
            raise ArgumentTypeError(f"prior: {type(prior).__name__}; expected \"shape\", \"weights\" or \"data\"")
        positions, weights, st = self._m.pose(
            json.dumps(obj),
            s,
            None if gamma is None else float(gamma),
            None if beta is None else float(beta),
            None if max_iterations is None else int(max_iterations),
            prior,
            None if spread is None else float(spread),
        )
        return Pose(positions, weights, st)

    def pose_parameters(self) -> list[str]:
        """The options of :meth:`pose` this model reads (e.g. ``["gamma"]``)."""
        return self._m.pose_parameters()

    def html(self, name: Optional[str] = None) -> str:
        """The standalone viewer page of the model (``meshdeco export --out view.html``): one
        HTML document with the neutral mesh, one blend target per component (for models whose
        decoding is not linear in the dials, e.g. the autoencoder, targets fitted by least
        squares, with the additivity error shown), sliders, heat maps and the training frames'
        weights. ``name``: the title (default: the artefact directory's name, else ``model``)."""
        if name is not None and not isinstance(name, str):
            raise ArgumentTypeError(f"name: {type(name).__name__} is not a str")
        return self._m.html(name)

    def show(self, *, height: int = 640, name: Optional[str] = None) -> Optional[View]:
        """Shows the model's standalone viewer page inline in a notebook (JupyterLab, classic
        Notebook, VS Code): sliders move the mesh, a component's name shows its heat map, the
        frames panel steps through the training frames. No server process: the page is in the
        notebook's output (an ``<iframe srcdoc>``), and it stays in the saved notebook. For
        click-and-drag posing run ``meshdeco view <model directory>``.

        In IPython it displays the page and returns ``None``; elsewhere it returns the
        :class:`View` (``view.save("model.html")``). ``height``: of the frame, CSS pixels."""
        if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or not 100 <= height <= 10000:
            raise ArgumentError(f"height: {height!r}; expected an integer number of pixels from 100 to 10000")
        view = View(self.html(name), int(height))
        try:
            from IPython import get_ipython  # type: ignore[import-not-found]
            from IPython.display import display  # type: ignore[import-not-found]
        except ImportError:
            return view
        if get_ipython() is None:
            return view
        display(view)
        return None

    def export(
        self,
        path: PathLike,
        *,
        animation: bool = False,
        fps: float = 30.0,
        colors: bool = False,
        up: str = "auto",
        bake: bool = False,
    ) -> dict[str, Any]:
        """Writes the model for other tools, as ``meshdeco export``: ``.glb`` (glTF 2.0: rest
        mesh plus one morph target per component, in rank order), ``.usda`` (USD blend
        shapes), ``.html`` (the standalone viewer page, as :meth:`show` displays it) or ``.h5``
        (a linear model in the SPLOCS reference's HDF5 layout: ``default``, ``tris``,
        ``comp000``…, ``weights``, ``verts``). ``animation``: key the training frames' weights at
        ``fps`` frames per second; ``colors``: a ``COLOR_0`` showing each component's support;
        ``up``: the data axis that becomes +Y (``auto``, ``x``, ``-z``, …); ``bake``: one target
        per training frame (these four: ``.glb`` and ``.usda`` only). Returns the report
        (targets, additivity Erms, bytes, …)."""
        return self._m.export(_path("path", path), bool(animation), float(fps), bool(colors), str(up), bool(bake))


def _terminal_progress() -> Optional[ProgressCallback]:
    stream = sys.stderr
    if not (hasattr(stream, "isatty") and stream.isatty()):
        return None
    state = {"stage": "", "total": 0}

    def show(stage: str, step: int, total: int, message: str) -> None:
        if stage:
            if state["stage"]:
                stream.write("\n")
            state["stage"], state["total"] = stage, total
            stream.write(f"{stage} …")
        else:
            of = f"/{state['total']}" if state["total"] else ""
            stream.write(f"\r\x1b[K{state['stage']} {step}{of} {message}")
        stream.flush()

    return show


def train(
    config: Union[Mapping[str, Any], PathLike],
    frames: Any = None,
    faces: Any = None,
    out: Optional[PathLike] = None,
    progress: Union[bool, ProgressCallback, None] = True,
    *,
    frame_names: Optional[Sequence[str]] = None,
) -> Model:
    """Trains a model, as ``meshdeco train --config``.

    ``config``: a dict with the TOML's structure (``{"name": …, "data": {…}, "method": {"kind":
    "splocs", …}}``; ``None`` values mean the key's default) or the path of a config file.
    ``frames`` ``(F, N, 3)`` and ``faces`` ``(T, 3)``: the data come from these arrays (no
    files; ``data.path`` is then only a label, ``"<arrays>"`` when absent), with the config's
    ``data.train`` / ``test`` / ``rest`` / ``align`` / ``unit_box`` applied to them;
    ``frame_names``: one name per frame (default ``frame_001``, …). ``out``: write the
    artefact directory there (as ``meshdeco train --out``); without it, nothing is kept on disk.

    ``progress``: ``True`` draws progress on a terminal (stderr), ``False``/``None`` is silent,
    or a callable ``progress(stage, step, total, message)`` (a new stage: ``stage`` non-empty,
    ``step`` 0; a step: ``stage`` empty). Ctrl-C (``KeyboardInterrupt``) stops training cleanly
    (the autoencoder at its next iteration) and re-raises; an exception raised by the callback
    stops it likewise. The GIL is released while the library works.

    Returns the trained :class:`Model` (``model.metrics``: train / test Erms, …).
    """
    if isinstance(config, Mapping):
        cfg: Any = dict(config)
    else:
        cfg = _path("config", config)
    f = fa = None
    if frames is not None:
        f = _floats("frames", frames, (None, None, 3), "(F, N, 3) positions")
    if faces is not None:
        fa = _faces("faces", faces)
    names = None
    if frame_names is not None:
        names = [str(n) for n in frame_names]
    if progress is True:
        cb = _terminal_progress()
    elif progress is False or progress is None:
        cb = None
    elif callable(progress):
        cb = progress
    else:
        raise ArgumentTypeError(f"progress: {type(progress).__name__}; expected True, False or a callable")
    o = None if out is None else _path("out", out)
    return Model(_native.train(cfg, f, fa, o, cb, names))


def load_model(directory: PathLike) -> Model:
    """Loads a trained model's artefact directory (``checkpoints/<name>``, as written by
    ``meshdeco train`` or :func:`train` with ``out``). Every file is verified against the
    manifest first; a missing directory is :class:`FileNotFound`, a damaged file an
    :class:`Error` naming it."""
    return Model(_native.load_model(_path("directory", directory)))
