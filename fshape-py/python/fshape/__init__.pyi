"""Functional shapes (meshes carrying a signal) and their metamorphoses.

After Charon, Charlier & Trouvé, "Metamorphoses of functional shapes in
Sobolev spaces". Arrays are numpy: float64 coordinates and signals, int64
cells. Every function raises FShapeError with the library's message (it
names the file, line, vertex or configuration key at fault), as one of its
kinds (InputError, ConfigError, CheckpointError, DivergenceError), and
releases the GIL while it computes.
"""

from os import PathLike
from typing import Any, Callable, Iterator, List, Literal, Mapping, Optional, Sequence, Tuple, TypedDict, Union, final, type_check_only

import numpy as np
import numpy.typing as npt

__version__: str

__all__ = [
    "FShapeError",
    "InputError",
    "ConfigError",
    "CheckpointError",
    "DivergenceError",
    "__version__",
    "FShape",
    "Config",
    "Geodesic",
    "MatchResult",
    "SubjectResult",
    "AtlasResult",
    "RegressionResult",
    "MapTest",
    "StatsResult",
    "ConfigLike",
    "Progress",
    "Correspondence",
    "read_mesh",
    "write_mesh",
    "read_signal",
    "read_mask",
    "read_label",
    "write_label",
    "write_signal",
    "read_parcellation",
    "write_parcellation",
    "read_cifti",
    "write_cifti",
    "signal_norm",
    "attachment",
    "attachment_grad",
    "quality",
    "shoot",
    "transport",
    "match",
    "atlas",
    "regress",
    "stats",
    "report",
]

@final
class Config:
    """A checked configuration, as a `fshape match` TOML file holds it
    (see the README's configuration reference). Errors name the key, and
    the line or file."""

    def __new__(cls, tables: Mapping[str, Any]) -> "Config":
        """From the TOML file's tables as nested dicts:
        {"deformation": {"widths": [0.4]}, "attachment": {...}}."""
    @staticmethod
    def from_toml(text: str) -> "Config":
        """From TOML text."""
    @staticmethod
    def read(path: Union[str, "PathLike[str]"]) -> "Config":
        """From a TOML file."""
    def to_toml(self) -> str:
        """Every key, defaults included, as TOML text."""
    def to_dict(self) -> dict[str, Any]:
        """Every key, defaults included, as nested dicts."""

ConfigLike = Union[Config, Mapping[str, Any], str, "PathLike[str]"]
"""What `shoot`, `match` and `atlas` take as their configuration: a
Config, the TOML tables as nested dicts, or a path to a TOML file (a
string is always a path; TOML text goes through Config.from_toml)."""

class FShapeError(ValueError):
    """Bad input or a failed computation; the message says what and where.
    Its subclasses say which kind; an error of none of them (writing a
    file failed, a run not finished) is an FShapeError itself."""

class InputError(FShapeError):
    """A file or value given is not what it must be (a malformed file, NaN
    where not allowed, an index out of range, mismatched lengths)."""

    path: Optional[str]
    """The file at fault, when it is a file."""
    line: Optional[int]
    """Its line (1-based), when it is text and the reader knows."""

class ConfigError(FShapeError):
    """The configuration: an unknown key, a value out of its range, bad TOML."""

class CheckpointError(FShapeError):
    """A checkpoint that is damaged, of another format, or of other inputs
    or settings than the run it is given to."""

class DivergenceError(FShapeError):
    """Shooting left finite numbers, collapsed a cell or drifted from the
    Hamiltonian it conserves: reduce the momenta or add time steps."""

@final
class FShape:
    """A functional shape: vertices (n x d, d = 2 or 3), cells (m x 2
    segments or m x 3 triangles), an optional signal (one value per vertex,
    or n x k for k maps per vertex) and an optional mask (a weight in
    [0, 1] per vertex; where it is 0 the signal has no value and is NaN, in
    every map). Immutable; every value is checked on
    creation (finite coordinates, a finite signal where the mask is
    positive, indices in range, no repeated index in a cell).
    """

    def __new__(
        cls,
        points: npt.ArrayLike,
        cells: npt.ArrayLike,
        signal: Optional[npt.ArrayLike] = None,
        mask: Optional[npt.ArrayLike] = None,
    ) -> "FShape": ...
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """The vertex coordinates, n x d (a copy)."""
    @property
    def cells(self) -> npt.NDArray[np.int64]:
        """The cells, m x 2 or m x 3 vertex indices (a copy)."""
    @property
    def signal(self) -> Optional[npt.NDArray[np.float64]]:
        """The signal, one value per vertex (n x k with k maps), or None."""
    @property
    def n_channels(self) -> int:
        """The maps per vertex (0 without a signal)."""
    @property
    def mask(self) -> Optional[npt.NDArray[np.float64]]:
        """The mask, one weight in [0, 1] per vertex, or None."""
    @property
    def dim(self) -> int:
        """The ambient dimension, 2 or 3."""
    @property
    def kind(self) -> Literal["triangle", "segment"]:
        """The cell kind."""
    @property
    def n_vertices(self) -> int: ...
    @property
    def n_cells(self) -> int: ...
    def with_mask(self, mask: Optional[npt.ArrayLike]) -> "FShape":
        """The same shape with another mask (or none); the signal is NaN where
        the mask is 0 and must be finite elsewhere."""
    def with_signal(self, signal: Optional[npt.ArrayLike]) -> "FShape":
        """The same shape with another signal (n values, n x k, or none); a
        mask is kept."""
    def validate(self) -> "Validation":
        """Errors and warnings, each with its code and a message naming the
        vertex or cell (unused vertices, zero-area cells, boundaries...)."""
    def coarsened(self) -> "FShape":
        """One level of icosahedral subdivision undone (icospheres, fsaverage
        meshes, whose first vertices are the coarser mesh's)."""
    def total_volume(self) -> float:
        """The total area (or length) of the cells."""

@type_check_only
class Finding(TypedDict):
    code: str
    message: str

@type_check_only
class Validation(TypedDict):
    errors: list[Finding]
    warnings: list[Finding]

@type_check_only
class Distance(TypedDict):
    value: float
    """A(X, Y), a squared distance."""
    xx: float
    xy: float
    yy: float

@type_check_only
class Quality(TypedDict):
    """How close a shape is to a target; distances are fractions of the
    target's bounding-box diagonal, signal errors of its signal's range."""

    diagonal: float
    mean_distance: float
    p95_distance: float
    max_distance: float
    target_within_1pct: float
    signal_rms: Optional[float]
    signal_p99: Optional[float]
    signal_rms_within_1pct: Optional[float]
    signal_rms_beyond_1pct: Optional[float]
    signal_roughness: Optional[float]
    signal_rms_on_shape: Optional[float]
    signal_rms_on_shape_beyond_1pct: Optional[float]
    shape_beyond_1pct: float
    signal_roughness_beyond_1pct: Optional[float]
    shape_past_boundary: float
    signal_rms_past_boundary: Optional[float]
    signal_roughness_past_boundary: Optional[float]
    signal_range: float

@type_check_only
class Energies(TypedDict):
    value: float
    """J = energy + gamma_W * A."""
    energy: float
    signal_energy: float
    attachment: float

@final
class Geodesic:
    """A geodesic at some times (what `shoot` returns, and each result's `geodesic`)."""

    @property
    def times(self) -> npt.NDArray[np.float64]: ...
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """T x n x d."""
    @property
    def signals(self) -> npt.NDArray[np.float64]:
        """T x n, or T x n x k with k maps."""
    @property
    def hamiltonian(self) -> npt.NDArray[np.float64]:
        """H at every integrator node."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

@type_check_only
class Alignment(TypedDict):
    """A pre-alignment ([prealign] in the configuration): T(x) = matrix (x, 1)
    from the source's frame to the target's."""
    kind: Literal["rigid", "similarity", "affine"]
    moving: Literal["source", "target"]
    """Which shape the registration moved (T on the source, T^-1 on the target)."""
    matrix: list[list[float]]
    """(d + 1) x (d + 1), row-major."""
    scale: float
    rotation_degrees: float
    translation: list[float]
    """The translation of the source's centroid."""
    attachment_before: float
    attachment_after: float
    start: int
    starts: int

@final
class MatchResult:
    """What `match` returns."""

    @property
    def stopped(self) -> bool:
        """True when the progress callback ended the run before its end: the
        rest is the result so far (the current momenta carried to the source
        and shot)."""
    @property
    def p0(self) -> npt.NDArray[np.float64]:
        """n x d."""
    @property
    def pf(self) -> npt.NDArray[np.float64]:
        """n, or n x k when the shapes carry k maps."""
    @property
    def energies(self) -> Energies: ...
    @property
    def quality(self) -> Quality:
        """How close the matched shape is to the target."""
    @property
    def initial_quality(self) -> Quality:
        """How close the template was."""
    @property
    def alignment(self) -> Optional[Alignment]:
        """With [prealign]: the map T; else None."""
    @property
    def stages(self) -> list[dict[str, Any]]:
        """Every stage's iterations (J at each)."""
    @property
    def iterations(self) -> int: ...
    @property
    def evaluations(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    @property
    def geodesic(self) -> Geodesic:
        """At the `times` given to `match`."""
    @property
    def matched(self) -> FShape:
        """The template shot to t = 1."""
    @property
    def target(self) -> FShape:
        """The target as matched (moved when [prealign] moves the target): with
        `matched`, what a `Correspondence` carries values between."""
    @property
    def config(self) -> dict[str, Any]:
        """The configuration with the weights used (for `shoot`)."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

@final
class SubjectResult:
    """One subject of an `AtlasResult`."""

    @property
    def p0(self) -> npt.NDArray[np.float64]: ...
    @property
    def pf(self) -> npt.NDArray[np.float64]:
        """n, or n x k when the shapes carry k maps."""
    @property
    def energies(self) -> Energies: ...
    @property
    def quality(self) -> Quality: ...
    @property
    def template_quality(self) -> Quality: ...
    @property
    def initial_attachment(self) -> float: ...
    @property
    def alignment(self) -> Optional[Alignment]:
        """The pre-alignment that moved this subject onto the initial template."""
    @property
    def geodesic(self) -> Geodesic: ...
    @property
    def matched(self) -> FShape:
        """The template shot onto this subject (the geodesic's end), vertex for
        vertex with the template: what `stats` compares."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

@final
class AtlasResult:
    """What `atlas` returns."""

    @property
    def template(self) -> FShape:
        """The estimated template."""
    @property
    def template_momenta(self) -> Optional[npt.NDArray[np.float64]]:
        """Hypertemplate model, else None."""
    @property
    def subjects(self) -> list[SubjectResult]: ...
    @property
    def energies(self) -> Energies:
        """Means over the subjects."""
    @property
    def stages(self) -> list[dict[str, Any]]: ...
    @property
    def iterations(self) -> int: ...
    @property
    def evaluations(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

@final
class RegressionResult:
    """What `regress` returns."""

    @property
    def p0(self) -> npt.NDArray[np.float64]:
        """Initial momenta on the baseline, n x d, per the span of ages."""
    @property
    def pf(self) -> npt.NDArray[np.float64]:
        """Signal momentum on the baseline, n (or n x k)."""
    @property
    def energies(self) -> dict[str, Any]:
        """value, energy, signal_energy, data and each visit's attachments."""
    @property
    def t0(self) -> float:
        """The earliest visit's age: t = (age - t0) / span."""
    @property
    def span(self) -> float: ...
    @property
    def times(self) -> npt.NDArray[np.float64]:
        """Each visit's t, in the visits' order."""
    @property
    def quality(self) -> list[Quality]:
        """Per visit: how close the fit at its age is to it."""
    @property
    def initial_quality(self) -> list[Quality]:
        """Per visit: how close the baseline is to it."""
    @property
    def alignments(self) -> list[Optional[Alignment]]:
        """Per visit, its map onto the baseline with [prealign]."""
    @property
    def fitted(self) -> list[FShape]:
        """The fit at each visit's age, on the baseline's mesh."""
    @property
    def rates(self) -> dict[str, npt.NDArray[np.float64]]:
        """Per unit age at the baseline's vertices: normal_velocity (surfaces
        and plane curves) and signal_rate (n, or n x k)."""
    @property
    def geodesic(self) -> Geodesic:
        """The fit at ages_out; its times are ages."""
    @property
    def baseline(self) -> FShape: ...
    @property
    def stages(self) -> list[dict[str, Any]]: ...
    @property
    def iterations(self) -> int: ...
    @property
    def evaluations(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    @property
    def config(self) -> dict[str, Any]:
        """The configuration with the weights used."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

Progress = Callable[[dict[str, Any]], Optional[bool]]
"""Called with {"event": "stage" | "iteration" | "stage_finished", ...};
returning True ends the run, as in scipy.optimize: `match` returns its
result so far (`stopped` True), `atlas` raises FShapeError naming the
checkpoint that resumes it. An exception raised by the callback ends the
run and propagates."""

def read_mesh(path: Union[str, "PathLike[str]"], signal_name: Optional[str] = None) -> FShape:
    """Reads PLY, OBJ, VTK legacy, GIfTI (.gii) or a FreeSurfer surface
    (lh.pial...), optionally gzipped; the signal is the per-vertex scalar
    named signal_name (default: "signal", if present)."""

def write_mesh(
    path: Union[str, "PathLike[str]"],
    shape: FShape,
    ascii: bool = False,
    *,
    gifti_encoding: Optional[Literal["ascii", "base64", "gzip-base64"]] = None,
    big_endian: bool = False,
    column_major: bool = False,
) -> None:
    """Writes the format the name says (.ply, .obj, .vtk, .gii, each
    optionally .gz, or a FreeSurfer name such as lh.pial), atomically.
    GIfTI files may choose their encoding (default gzip-base64, or ascii
    with ascii=True), byte order and index order; the other formats refuse
    these options."""

def read_signal(
    path: Union[str, "PathLike[str]"], allow_missing: bool = False
) -> Tuple[str, npt.NDArray[np.float64]]:
    """Reads a per-vertex signal (CSV column, GIfTI .shape.gii/.func.gii,
    FreeSurfer curv such as lh.thickness, .mgh/.mgz, or a CIFTI-2 map named
    as "maps.dscalar.nii:CORTEX_LEFT:thickness"): (name, values). With
    allow_missing, NaN (HCP's medial wall) is accepted as a missing value."""

def read_mask(path: Union[str, "PathLike[str]"], n_vertices: int) -> npt.NDArray[np.float64]:
    """Reads a mask for a surface of n_vertices vertices: a FreeSurfer .label
    (its vertices 1, the rest 0), regions of a parcellation named after it
    ("lh.aparc.annot:precentral,postcentral", also .label.gii, and
    "parcels.dlabel.nii:CORTEX_LEFT:V1_ROI" of a CIFTI-2 label file) or a
    per-vertex column of weights in [0, 1]."""

def write_signal(
    path: Union[str, "PathLike[str]"], values: npt.ArrayLike, name: str = "signal", faces: int = 0
) -> None:
    """Writes a per-vertex signal in the format the name says (.csv, .gii,
    .mgh/.mgz, lh.thickness...); faces is recorded by curv files."""

def signal_norm(shape: FShape, norm: Literal["l2-lumped", "l2", "h1"] = "h1", length: float = 1.0) -> float:
    """The squared signal norm f^T D_s(x) f (H1: P1 mass + length^2 x stiffness),
    summed over the maps when there are several."""

def attachment(
    source: FShape, target: FShape, kernel_geom: str, kernel_grass: str, kernel_signal: Optional[str] = None
) -> Distance:
    """The data attachment A(X, Y) of `fshape distance`; kernels as there:
    kernel_geom "gaussian:0.1", kernel_grass "binet" | "linear" |
    "gaussian-oriented:s" | "gaussian-unoriented:s", kernel_signal "gaussian:s"
    (or "gaussian:s1,s2,..." with a width per map)."""

def attachment_grad(
    source: FShape, target: FShape, kernel_geom: str, kernel_grass: str, kernel_signal: Optional[str] = None
) -> Tuple[Distance, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """A(X, Y) with its gradient in the source's vertices (n x d) and signal (n, or
    n x k with k maps)."""

def quality(shape: FShape, target: FShape) -> Quality:
    """How close shape is to target (the numbers every result reports)."""

def shoot(
    shape: FShape, p0: npt.ArrayLike, config: ConfigLike, pf: Optional[npt.ArrayLike] = None
) -> Geodesic:
    """The geodesic from shape with momenta p0 (n x d) and pf (n, or n x k for k maps) under the
    config's model (normalize must be false), at every time step."""

def transport(
    shape: FShape,
    p0: npt.ArrayLike,
    config: ConfigLike,
    beta: npt.ArrayLike,
    pf: Optional[npt.ArrayLike] = None,
    beta_f: Optional[npt.ArrayLike] = None,
    back: bool = False,
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Carries the momenta beta (n x d) and beta_f (n, or n x k) along the
    geodesic from shape with momenta p0 and pf (config's model; normalize
    must be false) by parallel transport, from its start to its end, or
    with back=True from its end to its start (a rate at a subject's shape,
    the end of a registration from a template, carried to the template).
    With back=True, beta is given at the geodesic's end. First order in the
    time step; masked vertices' signal momenta are 0, and LDDMM carries no
    signal momentum (zeros). It solves with the dense kernel matrix: at most
    4096 vertices, exact or truncated kernel sums. Returns the carried
    (beta, beta_f): beta_f is (n,) for one map, (n, k) for k."""

def match(
    source: FShape,
    target: FShape,
    config: ConfigLike,
    progress: Optional[Progress] = None,
    stage_templates: Optional[Sequence[FShape]] = None,
    times: Optional[Sequence[float]] = None,
    checkpoint: Union[str, "PathLike[str]", None] = None,
) -> MatchResult:
    """Registers source onto target as `fshape match` does; the result has
    the momenta, the geodesic at `times` (default 0, 0.25, ..., 1), the
    energies, the match quality, and the config with the weights used.

    With `checkpoint` (a path) the run writes its state there after every
    accepted iteration and, when the file exists, resumes from it: calling
    again with the same arguments continues a run stopped by the progress
    callback, Ctrl-C or a kill, to the same result bit for bit. A
    checkpoint written for other inputs or another config is refused.
    A progress callback returning True ends the run with its result so far,
    marked `stopped`."""

def atlas(
    subjects: Sequence[FShape],
    config: ConfigLike,
    template: Optional[FShape] = None,
    progress: Optional[Progress] = None,
    stage_templates: Optional[Sequence[FShape]] = None,
    checkpoint: Union[str, "PathLike[str]", None] = None,
) -> AtlasResult:
    """Estimates a metamorphosis atlas as `fshape atlas` does; `checkpoint`
    as for `match`. Subjects may carry several maps (n x k signals), the
    same k for every subject and the template."""

def regress(
    visits: Sequence[FShape],
    ages: Sequence[float],
    config: ConfigLike,
    weights: Optional[Sequence[float]] = None,
    progress: Optional[Progress] = None,
    ages_out: Optional[Sequence[float]] = None,
    checkpoint: Union[str, "PathLike[str]", None] = None,
) -> RegressionResult:
    """Fits one geodesic to a subject's visits at their ages as `fshape
    regress` does: the earliest visit is the baseline at t = 0, the ages
    map onto t in [0, 1]; each visit may be its own mesh. `checkpoint` as
    for `match`; a callback returning True ends the run without a result
    (call again with the checkpoint to continue)."""

@final
class MapTest:
    """One map's test in a `StatsResult`."""

    @property
    def kind(self) -> Literal["t", "F"]: ...
    @property
    def dof(self) -> Tuple[int, int]:
        """The contrast's rank and n - p."""
    @property
    def statistic(self) -> npt.NDArray[np.float64]: ...
    @property
    def effect(self) -> npt.NDArray[np.float64]:
        """t tests: the contrast's estimate per vertex (in the map's unit); F: its norm."""
    @property
    def p(self) -> npt.NDArray[np.float64]:
        """Uncorrected permutation p per vertex."""
    @property
    def p_fwe(self) -> npt.NDArray[np.float64]:
        """Family-wise error corrected p (maximum statistic)."""
    @property
    def tfce(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def tfce_p_fwe(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def critical(self) -> float:
        """The tested value (|t| when two-sided) that reaches p_FWE <= alpha."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

@final
class StatsResult:
    """What `stats` returns."""

    @property
    def design(self) -> dict[str, Any]:
        """columns (intercept first, a factor as `column[level]`), terms, x."""
    @property
    def contrast(self) -> dict[str, Any]: ...
    @property
    def rows_not_in_the_atlas(self) -> list[str]: ...
    @property
    def maps(self) -> dict[str, MapTest]:
        """By map: "signal" ("signal_2", ... for a template of several maps),
        "momentum", "displacement", "area"."""
    @property
    def multivariate(self) -> Optional[dict[str, Any]]:
        """With `scores`: statistic (Hotelling T^2 for a one-row contrast), p."""
    def __getitem__(self, key: str, /) -> Any:
        """The attribute named key (the results were dicts; a result is a
        read-only mapping of its attributes by name)."""
    def __contains__(self, key: object, /) -> bool: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]:
        """The attributes' names."""
    def values(self) -> list[Any]: ...
    def items(self) -> list[Tuple[str, Any]]: ...
    def get(self, key: str, default: Optional[Any] = None) -> Any: ...

def stats(
    atlas: AtlasResult,
    covariates: Union[str, "PathLike[str]", Mapping[str, Sequence[Any]]],
    contrast: str,
    maps: Optional[Sequence[str]] = None,
    columns: Optional[Sequence[str]] = None,
    permutations: int = 5000,
    seed: int = 0,
    tfce: bool = False,
    one_sided: bool = False,
    scores: Optional[npt.NDArray[np.float64]] = None,
    alpha: float = 0.05,
) -> StatsResult:
    """Where the atlas's subjects differ with a covariate, as `fshape
    stats` does: per-vertex maps on the template (signal change, normal
    momentum, normal displacement, log area change) tested with a general
    linear model and Freedman–Lane permutations (FWE by the maximum
    statistic; TFCE with `tfce`). `maps`: "signal" ("signal_2", … for
    the template's further maps), "momentum", "displacement", "area"
    (default: every one the template allows); the template's masked
    vertices are left out of every test. `covariates`: a CSV table whose first
    column names the subjects (index or `subject_003`), or a dict
    {column: one value per subject, in the atlas's order}; numbers enter
    as they are, names as a factor (treatment coding). `contrast`: a
    column's name, a design column or weights `0,1,0` (`;` between rows
    for an F test). `scores` (n × k): also Hotelling's test on them. The
    same seed gives the same bits."""

def report(
    path: Union[str, "PathLike[str]"],
    source: FShape,
    target: FShape,
    result: MatchResult,
    view: Tuple[float, float] = (30.0, 20.0),
) -> None:
    """Writes the report.html of a registration, as `fshape match` does:
    one file, viewable offline, with the geodesic in 3-D under a time
    slider and the target beside it, the match quality before and after,
    the stages and the configuration. `source` and `target` as given to
    `match`, `result` what it returned; `view` the camera's azimuth and
    elevation in degrees."""

def read_label(
    path: Union[str, "PathLike[str]"],
) -> Tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Reads a FreeSurfer label file: (vertices, points k x 3, values), as
    nibabel's read_label(path, read_scalars=True) reads the first and last."""

@type_check_only
class Carried(TypedDict):
    vertices: int
    beyond: int
    """Vertices farther than max_distance from the source."""
    missing: int
    """Vertices within it whose closest cell carries under half its weight
    on corners with a value."""

@final
class Correspondence:
    """Every vertex of `onto` at its closest point on `source` (the surface
    the values come from), computed once, as `fshape transfer` does. For a
    match result r, Correspondence(r.matched, r.target) carries the
    source's maps onto the target; Correspondence(r.target, r.matched)
    the target's back onto the source's vertices."""

    def __new__(cls, source: FShape, onto: FShape) -> "Correspondence": ...
    def map(
        self, values: npt.ArrayLike, max_distance: float = ...
    ) -> Tuple[npt.NDArray[np.float64], Carried]:
        """A map on source's vertices (NaN: no value) on onto's vertices:
        the barycentric mean at the closest point, corners without a value
        left out while the others carry at least half the weight, else NaN;
        NaN farther than max_distance (default: no limit)."""
    def labels(self, keys: npt.ArrayLike, max_distance: float = ...) -> npt.NDArray[np.int32]:
        """Integer keys on source's vertices (-1: no region) on onto's
        vertices: the key with the largest barycentric weight at the closest
        point (ties to the smaller key); -1 farther than max_distance."""
    @property
    def distances(self) -> npt.NDArray[np.float64]:
        """Each vertex of onto's distance to source."""
    def __len__(self) -> int: ...

def read_parcellation(
    path: Union[str, "PathLike[str]"],
) -> Tuple[npt.NDArray[np.int32], List[Tuple[int, str, Tuple[float, float, float, float]]]]:
    """Reads a FreeSurfer .annot, a GIfTI label array (.label.gii) or one
    surface structure of a CIFTI-2 label file (FILE.dlabel.nii:CORTEX_LEFT,
    :CORTEX_LEFT:MAP when it holds several maps): (keys, regions). Keys per
    vertex (.annot: the colour table's row, -1 without a region, as
    nibabel's read_annot; GIfTI and CIFTI: the label key, and CIFTI's
    vertices off the structure the table's ??? key); regions as (key,
    name, (red, green, blue, alpha)) in [0, 1]."""

def write_parcellation(
    path: Union[str, "PathLike[str]"],
    keys: npt.ArrayLike,
    regions: Sequence[Tuple[int, str, Tuple[float, float, float, float]]],
) -> None:
    """Writes a parcellation as read_parcellation returns it, in the format
    the path names: .annot (FreeSurfer: keys become the table's rows),
    .label.gii (GIfTI: keys and table kept; vertices in no region, -1,
    take the table's `???`) or .csv (a key per vertex)."""

def read_cifti(
    path: Union[str, "PathLike[str]"], structure: str, n_vertices: int, map: Optional[str] = None
) -> Tuple[str, npt.NDArray[np.float64]]:
    """Reads one map (name or number from 1; optional with one map) of a
    surface structure (CORTEX_LEFT) of a CIFTI-2 dense file on a surface of
    n_vertices vertices, NaN off the structure: (map name, values)."""

def write_cifti(
    path: Union[str, "PathLike[str]"],
    like: Union[str, "PathLike[str]"],
    structure: str,
    values: npt.ArrayLike,
    map: Optional[str] = None,
) -> None:
    """Writes values (one per surface vertex) as one map of a structure into
    a copy of the CIFTI-2 file like, every other byte kept; atomic."""

def write_label(
    path: Union[str, "PathLike[str]"],
    vertices: npt.ArrayLike,
    points: Optional[npt.ArrayLike] = None,
    values: Optional[npt.ArrayLike] = None,
    subject: str = "",
) -> None:
    """Writes a FreeSurfer label file (coordinates and values default to 0)."""
