"""Scene description: the typed tree a ``configs/scenes/*.toml`` file is loaded into.

Units: lengths are in scene units (world space, right-handed, y up), angles in
degrees, colours and alpha in [0, 1], screen sizes in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from gpusim.config import param
from gpusim.scene.camera import look_at
from gpusim.shaders import ShaderName

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class Screen:
    """The render target."""

    width: int = param(512, unit="px", doc="screen width", min=1, max=16384)
    height: int = param(512, unit="px", doc="screen height", min=1, max=16384)
    background: Vec3 = param((1.0, 1.0, 1.0), unit="RGB in [0,1]",
                             doc="colour every pixel is composited over")

    def __post_init__(self) -> None:
        if any(not 0.0 <= c <= 1.0 for c in self.background):
            raise ValueError("background components must lie in [0, 1]")


@dataclass(frozen=True, kw_only=True)
class Camera:
    """A perspective camera (OpenGL conventions: looks down -z in eye space)."""

    eye: Vec3 = param((0.0, 0.0, 5.0), unit="scene units", doc="camera position")
    target: Vec3 = param((0.0, 0.0, 0.0), unit="scene units", doc="point looked at")
    up: Vec3 = param((0.0, 1.0, 0.0), doc="up direction (need not be unit length)")
    fov_y_deg: float = param(45.0, unit="deg", doc="vertical field of view", gt=0.0, max=179.0)
    near: float = param(0.1, unit="scene units", doc="near clipping plane distance", gt=0.0)
    far: float = param(100.0, unit="scene units", doc="far clipping plane distance", gt=0.0)

    def __post_init__(self) -> None:
        if not self.far > self.near:
            raise ValueError(f"far ({self.far}) must be greater than near ({self.near})")
        if self.eye == self.target:
            raise ValueError("eye and target must differ")
        try:
            look_at(self.eye, self.target, self.up)
        except ValueError:
            raise ValueError("up: zero or parallel to the viewing direction (target - eye), which leaves the "
                             "camera's roll undefined; give another direction, e.g. up = [0.0, 1.0, 0.0]") from None


@dataclass(frozen=True, kw_only=True)
class Lighting:
    """One directional light for Lambert shading of per-vertex colours."""

    direction: Vec3 = param((0.4, 0.6, 1.0), doc="direction towards the light (world space)")
    ambient: float = param(0.35, unit="fraction", doc="light that reaches every surface", min=0.0, max=1.0)


@dataclass(frozen=True, kw_only=True)
class RasterOptions:
    """Rasterizer switches."""

    cull: Literal["none", "back", "front"] = param("none", doc="face culling (front = CCW)")


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """Fields every object has; ``kind`` selects the subclass (see :data:`OBJECT_KINDS`)."""

    registry: ClassVar[dict[str, type]] = {}

    kind: str = param(doc="object kind")
    translate: Vec3 = param((0.0, 0.0, 0.0), unit="scene units", doc="translation")
    rotate_deg: Vec3 = param((0.0, 0.0, 0.0), unit="deg", doc="rotation about x, then y, then z")
    scale: Vec3 = param((1.0, 1.0, 1.0), doc="scale factors along x, y, z")
    color: Vec3 = param((0.8, 0.8, 0.8), unit="RGB in [0,1]", doc="base colour")
    alpha: float = param(0.5, unit="[0,1]", doc="opacity of a transparent object", min=0.0, max=1.0)
    opaque: bool = param(False, doc="an opaque object: occludes what lies behind it")
    shading: Literal["lambert", "flat"] = param("lambert", doc="per-vertex Lambert shading or flat colour")

    def __post_init__(self) -> None:
        if any(not 0.0 <= c <= 1.0 for c in self.color):
            raise ValueError("color components must lie in [0, 1]")
        if self.shading == "lambert" and 0.0 in self.scale:
            raise ValueError(f"scale: {list(self.scale)} flattens the object, which leaves Lambert shading no "
                             f"normals; give non-zero scales or shading = \"flat\"")


def _register(name: str):
    def deco(cls):
        ObjectSpec.registry[name] = cls
        return cls
    return deco


@_register("sphere")
@dataclass(frozen=True, kw_only=True)
class Sphere(ObjectSpec):
    """A UV sphere (closed: two layers wherever it covers a pixel)."""

    radius: float = param(1.0, unit="scene units", doc="radius", gt=0.0)
    segments: int = param(32, unit="count", doc="divisions around the axis", min=3, max=4096)
    rings: int = param(16, unit="count", doc="divisions from pole to pole", min=2, max=4096)


@_register("box")
@dataclass(frozen=True, kw_only=True)
class Box(ObjectSpec):
    """An axis-aligned box centred on the origin (before the transform)."""

    size: Vec3 = param((1.0, 1.0, 1.0), unit="scene units", doc="edge lengths")


@_register("quad-grid")
@dataclass(frozen=True, kw_only=True)
class QuadGrid(ObjectSpec):
    """A flat rectangle in the xy plane split into nx x ny quads (2 triangles each)."""

    size: tuple[float, float] = param((2.0, 2.0), unit="scene units", doc="width and height")
    divisions: tuple[int, int] = param((1, 1), unit="count", doc="quads along x and y")

    def __post_init__(self) -> None:
        super().__post_init__()
        if min(self.divisions) < 1 or max(self.divisions) > 4096:
            raise ValueError("divisions must lie in 1..4096")


@_register("layered-quads")
@dataclass(frozen=True, kw_only=True)
class LayeredQuads(ObjectSpec):
    """``layers`` parallel quads stacked along -z: depth complexity ``layers`` where they overlap.

    ``spacing`` 0 gives coplanar (equal-depth) layers. ``colors`` and ``alphas``,
    when given, are cycled over the layers. ``order`` is the submission order.
    """

    layers: int = param(8, unit="count", doc="number of quads", min=1, max=1_000_000)
    spacing: float = param(0.1, unit="scene units", doc="distance between layers", min=0.0)
    size: tuple[float, float] = param((2.0, 2.0), unit="scene units", doc="quad width and height")
    colors: tuple[Vec3, ...] = param((), unit="RGB in [0,1]", doc="per-layer colours, cycled")
    alphas: tuple[float, ...] = param((), unit="[0,1]", doc="per-layer alphas, cycled")
    order: Literal["front-to-back", "back-to-front", "random"] = param(
        "back-to-front", doc="submission order of the layers")
    seed: int = param(0, doc="seed of the random order")

    def __post_init__(self) -> None:
        super().__post_init__()
        if any(not 0.0 <= c <= 1.0 for rgb in self.colors for c in rgb):
            raise ValueError("colors components must lie in [0, 1]")
        if any(not 0.0 <= a <= 1.0 for a in self.alphas):
            raise ValueError("alphas must lie in [0, 1]")


@_register("sliver-fan")
@dataclass(frozen=True, kw_only=True)
class SliverFan(ObjectSpec):
    """``count`` thin triangles fanning out from the origin over ``arc_deg``: sliver stress."""

    count: int = param(64, unit="count", doc="number of triangles", min=1, max=1_000_000)
    radius: float = param(1.0, unit="scene units", doc="length of each sliver", gt=0.0)
    arc_deg: float = param(90.0, unit="deg", doc="angle the whole fan spans", gt=0.0, max=360.0)


@_register("leaves")
@dataclass(frozen=True, kw_only=True)
class Leaves(ObjectSpec):
    """``count`` randomly placed and oriented quads in a cube of side ``spread``: foliage.

    They cross each other freely, the case where per-block depth sorting of
    whole triangles fails (seed 002's invalid pixels in foliage scenes).
    Colours vary by up to ``color_jitter`` around ``color``.
    """

    count: int = param(2000, unit="count", doc="number of leaves (2 triangles each)", min=1, max=1_000_000)
    size: tuple[float, float] = param((0.3, 0.1), unit="scene units", doc="leaf length and width")
    spread: float = param(2.0, unit="scene units", doc="side of the cube the leaf centres fill", gt=0.0)
    color_jitter: float = param(0.2, unit="[0,1]", doc="largest change of each colour channel", min=0.0, max=1.0)
    seed: int = param(0, doc="seed of the placement")


@_register("tet-ventricle")
@dataclass(frozen=True, kw_only=True)
class TetVentricle(ObjectSpec):
    """A tetrahedral volume mesh of a heart ventricle, every tetrahedron face drawn as a transparent triangle.

    The solid is a block of prolate spheroidal coordinates, cardiac mechanics' standard left-ventricle
    geometry: x = focal cosh(lambda) cos(mu) (the long axis, apex at +x), y = focal sinh(lambda) sin(mu)
    cos(theta), z = focal sinh(lambda) sin(mu) sin(theta), over ``lambda_range`` (the wall, cavity side
    first), ``mu_range_deg`` (apex to base; an apex of 0 closes the tip) and ``theta_range_deg`` (a full
    360 closes the ring). It is cut into ``divisions`` cells, each split into 6 tetrahedra (the Kuhn split,
    conforming across cells); cells shrink in theta towards the apex and the tip's ring collapses, so
    many tetrahedra are long and skinny. ``jitter`` moves each vertex off its grid point by up to that
    fraction of a cell (seeded), never across the surface. Each face is drawn once. The colour blends from
    ``inner_color`` on the cavity side to ``color`` outside; every vertex has the object's ``alpha``.
    """

    focal: float = param(1.0, unit="scene units", doc="focal distance of the prolate spheroidal coordinates",
                         gt=0.0)
    lambda_range: tuple[float, float] = param((0.6, 1.0), unit="1 (radial coordinate)",
                                              doc="radial coordinate of the cavity side and of the outside")
    mu_range_deg: tuple[float, float] = param((0.0, 120.0), unit="deg",
                                              doc="angle from the long axis: apex end, base end")
    theta_range_deg: tuple[float, float] = param((0.0, 360.0), unit="deg", doc="angle around the long axis")
    divisions: tuple[int, int, int] = param((6, 100, 50), unit="cells",
                                            doc="cells along lambda, mu and theta (6 tetrahedra each)")
    jitter: float = param(0.3, unit="fraction of a cell", doc="largest move of a vertex off its grid point",
                          min=0.0, max=0.45)
    seed: int = param(0, doc="seed of the jitter")
    inner_color: Vec3 = param((0.45, 0.05, 0.08), unit="RGB in [0,1]", doc="colour on the cavity side")

    def __post_init__(self) -> None:
        super().__post_init__()
        lo, hi = self.lambda_range
        if not 0.0 < lo < hi <= 4.0:
            raise ValueError(f"lambda_range: {list(self.lambda_range)} must satisfy 0 < inner < outer <= 4, "
                             "e.g. [0.6, 1.0]")
        apex, base = self.mu_range_deg
        if not 0.0 <= apex < base <= 180.0:
            raise ValueError(f"mu_range_deg: {list(self.mu_range_deg)} must satisfy 0 <= apex < base <= 180, "
                             "e.g. [0.0, 120.0]")
        start, end = self.theta_range_deg
        if not 0.0 < end - start <= 360.0:
            raise ValueError(f"theta_range_deg: {list(self.theta_range_deg)} must span more than 0 and at most "
                             "360 degrees, e.g. [0.0, 360.0]")
        if any(not 1 <= d <= 1024 for d in self.divisions) or (end - start == 360.0 and self.divisions[2] < 3):
            raise ValueError(f"divisions: {list(self.divisions)} must lie in 1..1024 (at least 3 around a closed "
                             "ring), e.g. [6, 100, 50]")
        if any(not 0.0 <= c <= 1.0 for c in self.inner_color):
            raise ValueError("inner_color components must lie in [0, 1]")


@_register("mesh")
@dataclass(frozen=True, kw_only=True)
class Mesh(ObjectSpec):
    """A triangle mesh file (OBJ, PLY, OFF, STL; read with trimesh).

    A relative ``path`` is resolved against the scene file's folder. With
    ``normalize`` the mesh is centred and scaled to fit a unit-radius sphere.
    """

    path: str = param(doc="mesh file")
    normalize: bool = param(True, doc="centre and scale the mesh into the unit sphere")
    install_hint: str = param("", doc="what to tell the user when the file is missing")


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A whole scene file."""

    name: str = param("scene", doc="scene name, recorded in the trace")
    description: str = param("", doc="one line about the scene")
    screen: Screen = param(Screen())
    camera: Camera = param(Camera())
    lighting: Lighting = param(Lighting())
    fragment_shader: ShaderName = param("none", doc="the material program each shaded fragment runs, timed in "
                                        "every scheme's shading passes (gpusim.shaders: 'none', the trace's "
                                        "colours are final; 'lucid-simple', LucidRaster's hardware renderer)")
    raster: RasterOptions = param(RasterOptions())
    objects: tuple[ObjectSpec, ...] = param((), doc="objects in submission order")
    subdivide_budget: float = param(1.0, unit="x the scene's triangles",
                                    doc="split triangles, worst aspect ratio first, until the scene has this many "
                                        "times its triangles (seed 004 section 4.3; 1: none)", min=1.0, max=64.0)

    def __post_init__(self) -> None:
        if not self.objects:
            raise ValueError("a scene needs at least one [[objects]] table")


OBJECT_KINDS = ObjectSpec.registry
