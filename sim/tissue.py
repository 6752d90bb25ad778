"""The soft tissue flap: a procedurally meshed PyBullet deformable pinned on three edges.

The flap is a mass-spring cloth (``useMassSpring``), not an FEM volume: a retracted flap is thin, a
cloth has one layer of nodes (tens, not hundreds, for the same area), and every spring's force is
``k (length - rest)`` along the spring, so the retraction force on the grasp can be computed exactly
from the node positions (see :mod:`sim.mechanics`). Its material is given in physical units (Young's
modulus, thickness, density); :mod:`sim.material` derives the spring constant of its lattice. PyBullet's
deformable solver treats the elastic
springs explicitly, so the stable time step shrinks as ``sqrt(node mass / k)``: a coarse mesh with
heavier nodes is both faster and more stable than the 15 x 15 cloth of the paper's code.

Layout in the tissue's own frame: the flap spans ``[-L/2, L/2]^2`` in x and y; the edges at
``y = -L/2`` (back) and ``x = +-L/2`` (sides) are pinned, the edge at ``y = +L/2`` is the free flap.

The flap's look is its colour times a procedural texture (seeded blotches and vessel-like streaks, see
:func:`texture_image`). The mesh carries texture coordinates, which do not change the simulation: the
nodes move bit for bit as without them (measured), and PyBullet's CPU renderer maps the texture onto
the deforming cloth.
"""

from __future__ import annotations

import atexit
import collections
import functools
import itertools
import os
import shutil
import struct
import tempfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from psm_control.errors import ConfigurationError
from sim.mechanics import spring_forces
from sim.quiet_pybullet import pybullet as p
from sim.tissue_params import SITE_NAMES, TissueParams

__all__ = [
    "SITE_NAMES",
    "Tissue",
    "TissueParams",
    "cached_file",
    "grid_mesh",
    "marked_texture_file",
    "read_texture",
    "texture_file",
    "texture_image",
]


def grid_mesh(resolution: int, size_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and counter-clockwise triangles (T, 3) of a square grid in the z = 0 plane.

    Each cell is split by one diagonal, alternating in a checkerboard, so the lattice of its edges is
    isotropic in the plane (:mod:`sim.material`).
    """
    xs = np.linspace(-size_m / 2.0, size_m / 2.0, resolution)
    gx, gy = np.meshgrid(xs, xs)
    vertices = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    return vertices, _grid_topology(resolution)[0].copy()


# The flap's size is drawn per episode and its resolution is not: its triangles and springs are listed once.
@functools.cache
def _grid_topology(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (T, 3) of :func:`grid_mesh` and the node pairs (E, 2) of their edges, sorted (read-only)."""
    listed = []
    for j in range(resolution - 1):
        for i in range(resolution - 1):
            a = j * resolution + i
            b, c = a + 1, a + resolution
            if (i + j) % 2 == 0:
                listed += [(a, b, c + 1), (a, c + 1, c)]
            else:
                listed += [(a, b, c), (b, c + 1, c)]
    triangles = np.array(listed, dtype=int)
    pairs = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges = np.unique(np.sort(pairs, axis=1), axis=0)
    triangles.flags.writeable = edges.flags.writeable = False
    return triangles, edges


#: Side of the square texture images [px].
TEXTURE_SIZE_PX = 64
_CACHE_SIZE = 64  # files (textures and meshes) kept per process
_PREFIX = "tissue_retract_"  # of the per-process temporary directories


def _smooth_noise(rng: np.random.Generator, cells: int, size: int) -> np.ndarray:
    """A (size, size) field in [0, 1]: a random (cells + 1)^2 grid, bilinearly interpolated."""
    grid = rng.random((cells + 1, cells + 1))
    coords = np.linspace(0.0, cells, size)
    i0 = np.minimum(coords.astype(int), cells - 1)
    t = coords - i0
    rows = grid[i0] * (1.0 - t)[:, None] + grid[i0 + 1] * t[:, None]
    return np.asarray(rows[:, i0] * (1.0 - t)[None, :] + rows[:, i0 + 1] * t[None, :])


def texture_image(seed: int, size: int = TEXTURE_SIZE_PX) -> np.ndarray:
    """The flap's procedural texture for ``seed``: (size, size, 3) uint8, to be multiplied by its colour.

    Blotches (two octaves of smooth noise) darken the surface by up to about 30 %; vessel-like streaks
    (a thin band around a level set of a third noise field, so they meander and branch) darken green
    and blue more than red, so on a pink flap they read as dark red vessels. The same seed always
    gives the same image.
    """
    rng = np.random.default_rng([int(seed), 0x7E57])
    blotches = 0.6 * _smooth_noise(rng, 4, size) + 0.4 * _smooth_noise(rng, 9, size)
    shade = 1.0 - 0.3 * blotches
    level = _smooth_noise(rng, 5, size)
    width = 0.02 + 0.015 * rng.random()
    vessels = np.exp(-(((level - rng.uniform(0.35, 0.65)) / width) ** 2))
    darkening = np.array([0.3, 0.6, 0.5])
    image = shade[:, :, None] * (1.0 - vessels[:, :, None] * darkening)
    return np.asarray(np.clip(np.rint(255.0 * image), 0, 255), dtype=np.uint8)


def _write_png(path: str, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image as an 8-bit RGB PNG."""
    height, width, _ = image.shape
    raw = b"".join(b"\x00" + image[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(
            b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
        )


class _Files:
    """This process's temporary directory for meshes and textures, removed when the process exits.

    Keyed by process id, so that a forked worker (vectorised environments) writes and removes its own. The
    directory's name carries the process id (``tissue_retract_<pid>_*``): a process that ends without its
    exit handlers (killed, or a pool worker leaving by ``os._exit``) leaves its directory behind, and the
    next process to make one removes every such directory whose process is gone, so they never accumulate.
    """

    def __init__(self) -> None:
        self.pid = -1
        self.directory = ""
        self.cache: collections.OrderedDict[str, None] = collections.OrderedDict()

    def path(self, name: str) -> str:
        if self.pid != os.getpid():
            self.pid = os.getpid()
            _remove_orphaned_directories()
            self.directory = tempfile.mkdtemp(prefix=f"{_PREFIX}{self.pid}_")
            self.cache.clear()
            atexit.register(_remove_directory, self.pid, self.directory)
        return os.path.join(self.directory, name)

    def get(self, name: str, write: Callable[[str], None]) -> str:
        """Path of the file ``name``, written by ``write(path)`` unless cached; old files are removed."""
        path = self.path(name)
        if name in self.cache:
            self.cache.move_to_end(name)
            return path
        write(path)
        self.cache[name] = None
        while len(self.cache) > _CACHE_SIZE:
            old, _ = self.cache.popitem(last=False)
            os.remove(self.path(old))
        return path


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _remove_orphaned_directories() -> None:
    """Remove the ``tissue_retract_<pid>_*`` directories of processes that no longer run."""
    for path in Path(tempfile.gettempdir()).glob(f"{_PREFIX}*_*"):
        pid_text = path.name[len(_PREFIX) :].split("_", 1)[0]
        if pid_text.isdigit() and path.is_dir() and not _process_alive(int(pid_text)):
            shutil.rmtree(path, ignore_errors=True)


def _remove_directory(pid: int, directory: str) -> None:
    if os.getpid() == pid:  # not a forked child's inherited exit handler
        shutil.rmtree(directory, ignore_errors=True)


_FILES = _Files()


def cached_file(name: str, write: Callable[[str], None]) -> str:
    """Path of this process's temporary file ``name``, written by ``write(path)`` once and cached."""
    return _FILES.get(name, write)


def texture_file(seed: int) -> str:
    """Path of the PNG of :func:`texture_image` for ``seed``, written once per process and cached."""
    seed = int(seed)
    return _FILES.get(f"texture_{seed}.png", lambda path: _write_png(path, texture_image(seed)))


#: Side of a texture with inked sites [px]: 0.3 mm per pixel on the 8 cm flap, so a dot is round.
MARKED_TEXTURE_PX = 256
#: Radius of an inked site, as a fraction of the texture's side (2 mm on the 8 cm flap).
INK_DOT_RADIUS = 0.025


def marked_texture_file(path: str | None, seed: int | None, points_uv: list[np.ndarray]) -> str:
    """A texture with a dark dot at each ``points_uv`` (texture coordinates, u along x, v along y).

    The base is the image at ``path`` or the procedural texture of ``seed`` (flat without either).
    """
    size = MARKED_TEXTURE_PX
    if path is not None:
        base = read_texture(path, size)
    elif seed is not None:
        small = texture_image(int(seed))
        base = np.repeat(np.repeat(small, size // small.shape[0], axis=0), size // small.shape[1], axis=1)
    else:
        base = np.full((size, size, 3), 255, dtype=np.uint8)
    image = base.copy()
    rows, cols = np.mgrid[0:size, 0:size]
    for u, v in points_uv:
        # PyBullet's renderer reads texture row 0 at v = 1 (found by projecting inked sites into renders).
        dot = (cols + 0.5 - u * size) ** 2 + (rows + 0.5 - (1.0 - v) * size) ** 2 <= (INK_DOT_RADIUS * size) ** 2
        image[dot] = (40, 25, 60)
    key = zlib.crc32(image.tobytes())
    return _FILES.get(f"marked_{key:08x}.png", lambda out: _write_png(out, image))


def read_texture(path: str, size: int) -> np.ndarray:
    """An image file as a (size, size, 3) uint8 texture (resized, alpha dropped)."""
    from PIL import Image  # Pillow comes with matplotlib and imageio

    with Image.open(path) as picture:
        return np.asarray(picture.convert("RGB").resize((size, size)), dtype=np.uint8)


def _obj_file(resolution: int) -> str:
    """Path of the flap's OBJ mesh of unit size, with texture coordinates, written once per process and cached.

    One file per resolution, scaled to the flap's size when loaded: PyBullet keeps every mesh file it has
    parsed for the life of the process, so a file per randomized size grew a sweep's workers by about 8 kB
    an episode, without bound (measured: 2.4 MB over 300 sizes, none with one file and ``scale``).
    """

    def write(path: str) -> None:
        vertices, triangles = grid_mesh(resolution, 1.0)
        uv = vertices[:, :2] + 0.5  # the texture spans the flat flap once
        lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in vertices]
        lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in triangles]
        with open(path, "w") as f:
            f.write("\n".join(lines) + "\n")

    return _FILES.get(f"flap_{resolution}.obj", write)


class Tissue:
    """The flap loaded into one physics client (which must use the deformable world).

    Args:
        client: PyBullet physics client id.
        params: The flap's settings.
        origin: World position of the flap's centre [m].
        pin_edges: Pin the back and side edges to the world (False leaves the flap free, for tests).
    """

    def __init__(self, client: int, params: TissueParams, origin: np.ndarray, *, pin_edges: bool = True) -> None:
        self.client = client
        self.params = params
        self.origin = np.asarray(origin, dtype=float)
        vertices, self.triangles = grid_mesh(params.resolution, params.size_m)
        self.rest_positions = vertices + self.origin
        self.body_id = p.loadSoftBody(
            _obj_file(params.resolution),
            basePosition=self.origin.tolist(),
            scale=params.size_m,
            mass=params.mass_kg,
            useMassSpring=1,
            useBendingSprings=0,
            # PyBullet's default (0.5) adds stiffness to every spring even without bending springs: measured,
            # 0.3 N/m more membrane stiffness, a third of the sheet's at E t = 1 N/m, and missing from the force.
            springBendingStiffness=0.0,
            useNeoHookean=0,
            springElasticStiffness=params.spring_stiffness_n_per_m,
            springDampingStiffness=params.damping,
            springDampingAllDirections=1,
            useSelfCollision=0,
            frictionCoeff=params.friction,
            collisionMargin=0.001,
            physicsClientId=client,
        )
        # Bullet puts a body to sleep after 2 s below its speed threshold; a sleeping flap stays frozen while
        # an anchored grasp drags one node through it (measured: a 2 cm lift moved the neighbours 0 mm, and
        # the spring forces of that artefact read up to 2 N in an episode whose true peak was 0.2 N).
        p.changeDynamics(self.body_id, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=client)
        p.changeVisualShape(self.body_id, -1, rgbaColor=list(params.rgba), physicsClientId=client)
        self._texture_pending = params.texture_seed is not None or params.texture_path is not None or params.mark_sites
        self.edges = _grid_topology(params.resolution)[1].copy()
        self.rest_lengths = np.linalg.norm(vertices[self.edges[:, 1]] - vertices[self.edges[:, 0]], axis=1)
        self.node_mass_kg = self._lumped_masses(vertices)
        n = params.resolution
        rows, cols = np.divmod(np.arange(n * n), n)
        self.grid_rows, self.grid_cols = rows, cols
        self.pinned = np.flatnonzero((rows == 0) | (cols == 0) | (cols == n - 1)) if pin_edges else np.zeros(0, int)
        for node in self.pinned:
            p.createSoftBodyAnchor(self.body_id, int(node), -1, -1, physicsClientId=client)
        half = params.size_m / 2.0
        edge_y = half - params.site_inset_m
        self.site_local = {
            "centre": np.array([0.0, edge_y, 0.0]),
            "left": np.array([-params.site_spacing_m, edge_y, 0.0]),
            "right": np.array([params.site_spacing_m, edge_y, 0.0]),
        }

    def show_texture(self) -> None:
        """Put the texture (procedural, the user's image, inked sites) on the flap, once, before its first render.

        Not at construction: drawing and loading a texture costs about a millisecond per episode, and most
        episodes (training, evaluation) are never rendered.
        """
        if self._texture_pending:
            params = self.params
            if params.mark_sites:
                offset = np.asarray(params.site_offset_m, dtype=float)
                points = [(local[:2] + offset) / params.size_m + 0.5 for local in self.site_local.values()]
                path = marked_texture_file(params.texture_path, params.texture_seed, points)
            elif params.texture_path is not None:
                path = params.texture_path
            else:
                path = texture_file(int(params.texture_seed or 0))
            texture = p.loadTexture(path, physicsClientId=self.client)
            p.changeVisualShape(self.body_id, -1, textureUniqueId=texture, physicsClientId=self.client)
        self._texture_pending = False

    def _lumped_masses(self, vertices: np.ndarray) -> np.ndarray:
        """Node masses by a third of the adjacent triangle areas, as Bullet's ``setTotalMass(m, true)``."""
        a, b, c = (vertices[self.triangles[:, k]] for k in range(3))
        areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        masses = np.zeros(len(vertices))
        for k in range(3):
            np.add.at(masses, self.triangles[:, k], areas / 3.0)
        return masses * (self.params.mass_kg / masses.sum())

    def positions(self) -> np.ndarray:
        """Current node positions (N, 3) in the world [m]."""
        _, nodes = p.getMeshData(self.body_id, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=self.client)
        # Twice per step: reading the tuples as one flat stream takes half the time of np.asarray (measured).
        return np.fromiter(itertools.chain.from_iterable(nodes), float, count=3 * len(nodes)).reshape(-1, 3)

    def elastic_forces(self, positions: np.ndarray) -> np.ndarray:
        """The elastic force (N, 3) [N] the springs exert on every node at ``positions``."""
        return spring_forces(positions, self.edges, self.rest_lengths, self.params.spring_stiffness_n_per_m)

    def site_binding(self, local_point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The triangle holding a material point of the flat flap, and its barycentric weights."""
        rest = self.rest_positions - self.origin
        a, b, c = (rest[self.triangles[:, k], :2] for k in range(3))
        # Every triangle's 2 x 2 system in one call: the same LAPACK solve per triangle as one call each.
        matrices = np.stack([b - a, c - a], axis=2)
        u, v = np.linalg.solve(matrices, (local_point[:2] - a)[:, :, None])[:, :, 0].T
        inside = np.flatnonzero((u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9))
        if inside.size == 0:
            raise ConfigurationError("site", local_point.tolist(), "a point inside the flap")
        first = inside[0]
        return self.triangles[first].copy(), np.array([1.0 - u[first] - v[first], u[first], v[first]])
