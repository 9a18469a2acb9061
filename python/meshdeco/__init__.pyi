"""Type stubs of meshdeco (arrays: float64 positions in data units, int64 faces)."""

import os
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence, Union, overload, Literal

import numpy as np
import numpy.typing as npt

from ._errors import (
    ArgumentError as ArgumentError,
    ArgumentTypeError as ArgumentTypeError,
    ConfigError as ConfigError,
    Error as Error,
    FileError as FileError,
    FileNotFound as FileNotFound,
    InvalidInput as InvalidInput,
    NumericalError as NumericalError,
    ParseError as ParseError,
)

__version__: str

PathLike = Union[str, os.PathLike[str]]
Float64Array = npt.NDArray[np.float64]
Int64Array = npt.NDArray[np.int64]
ProgressCallback = Callable[[str, int, int, str], None]

def load_mesh(path: PathLike) -> tuple[Float64Array, Int64Array]:
    """(vertices (N, 3), faces (T, 3)) of an OBJ / PLY / OFF file."""

@overload
def load_sequence(path: PathLike, *, return_names: Literal[False] = ...) -> tuple[Float64Array, Int64Array]: ...
@overload
def load_sequence(path: PathLike, *, return_names: Literal[True]) -> tuple[Float64Array, Int64Array, list[str]]: ...
def save_mesh(path: PathLike, vertices: npt.ArrayLike, faces: npt.ArrayLike) -> None:
    """Writes (N, 3) vertices and (T, 3) faces; format from the extension (.obj, .ply, .off)."""

class Pose(NamedTuple):
    positions: Float64Array
    """(N, 3), data units."""
    weights: Float64Array
    """(K,), model coordinates."""
    start: Float64Array
    """(N, 3), data units."""

class View:
    html: str
    height: int
    def __init__(self, html: str, height: int = ...) -> None: ...
    def _repr_html_(self) -> str:
        """An <iframe srcdoc> holding the page."""
    def save(self, path: PathLike) -> None: ...

class Model:
    @property
    def kind(self) -> str: ...
    @property
    def representation(self) -> str: ...
    @property
    def n_components(self) -> int: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def rest(self) -> Float64Array:
        """(N, 3), data units."""
    @property
    def faces(self) -> Int64Array:
        """(T, 3)."""
    @property
    def train_frames(self) -> list[str]: ...
    @property
    def train_weights(self) -> Optional[Float64Array]:
        """(F, K) or None."""
    @property
    def metrics(self) -> Optional[dict[str, Any]]: ...
    @property
    def directory(self) -> Optional[str]: ...
    def components(self) -> list[dict[str, Any]]:
        """[{index, rank, name, centre, magnitude (N,)}] in index order."""
    def encode(self, frames: npt.ArrayLike) -> Float64Array:
        """(F, N, 3) → (F, K); (N, 3) → (K,)."""
    def decode(self, weights: npt.ArrayLike) -> Float64Array:
        """(F, K) → (F, N, 3); (K,) → (N, 3)."""
    def synthesize(self, dials: npt.ArrayLike) -> Float64Array:
        """(K,) dials → (N, 3)."""
    def pose(
        self,
        targets: Mapping[int, npt.ArrayLike],
        start: Optional[npt.ArrayLike] = None,
        *,
        gamma: Optional[float] = None,
        beta: Optional[float] = None,
        max_iterations: Optional[int] = None,
        prior: Optional[Literal["shape", "weights"]] = None,
        spread: Optional[float] = None,
    ) -> Pose:
        """{vertex: (x, y, z)} targets in data units → Pose((N, 3), (K,), (N, 3))."""
    def pose_parameters(self) -> list[str]: ...
    def html(self, name: Optional[str] = None) -> str:
        """The standalone viewer page (one HTML document)."""
    def show(self, *, height: int = 640, name: Optional[str] = None) -> Optional[View]:
        """Displays the page inline in Jupyter (returns None there); elsewhere returns the View."""
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
        """Writes .glb (glTF 2.0 morph targets), .usda (USD blend shapes), .html (the standalone
        page) or .h5 (the SPLOCS reference's HDF5 layout)."""

def train(
    config: Union[Mapping[str, Any], PathLike],
    frames: Optional[npt.ArrayLike] = None,
    faces: Optional[npt.ArrayLike] = None,
    out: Optional[PathLike] = None,
    progress: Union[bool, ProgressCallback, None] = True,
    *,
    frame_names: Optional[Sequence[str]] = None,
) -> Model:
    """Trains from a config dict or file; frames (F, N, 3) + faces (T, 3) replace the data files."""

def load_model(directory: PathLike) -> Model:
    """Loads an artefact directory."""
