"""Compare mesa's convex parts with V-HACD and CoACD on the real GLBs of ../shared/realdata/glb.

Setup (once; the peers are not CI dependencies, keep them out of scripts/requirements-tools.txt):

    python3 -m venv .venv-bench
    .venv-bench/bin/pip install trimesh numpy scipy rtree vhacdx coacd
    cargo build --release -p mesa-pipeline --bin mesa
    cargo build --release -p mesa-stages --example table_mesh

Run (or bench/compare_decomposition.sh, which does the builds too):

    .venv-bench/bin/python bench/compare_decomposition.py [--glb-dir ../shared/realdata/glb]
        [--out target/bench-decomposition] [--coacd-timeout-s 45] [--coacd-max-triangles 0]

For every top-level GLB that `mesa assets` indexes as valid (the deliberately invalid files —
glTF 1.0, external URI, unsupported extension, no mesh, zero-size — are listed as skipped with
mesa's reason code):

* **the mesh**: exactly the triangles mesa decomposes, written by the `table_mesh` example:
  every placed triangle in metres, in the asset's table-aligned frame (glTF (X, Y, Z) ->
  (X, -Z, Y); no front yaw, as for an asset without annotation). mesa's parts
  (`assets/index/shapes/<uid>.json`, `parts[].points_m`) are in that same frame and unit, so
  they are compared as stored, with no transform. V-HACD and CoACD get the same vertices and
  triangles. Where trimesh can also load the GLB itself, its bounds (converted the same way)
  are checked against that mesh as an independent check of the frame.
* **mesa**: a dataset whose `assets/library` holds only that GLB, `target/release/mesa assets`
  on it (default configuration), wall time of the whole command.
* **V-HACD**: `vhacdx.compute_vhacd` with its defaults (64 hulls at most, 400k voxels).
* **CoACD**: `coacd.run_coacd` (threshold 0.05, seed 0) at a reduced search effort so that
  the bench stays near 15 minutes on 2 cores: `--coacd-mcts-iterations 50` (default 150),
  `--coacd-mcts-nodes 10` (20), `--coacd-resolution 1000` (2000); in a child process stopped
  after `--coacd-timeout-s` (45 s); meshes above `--coacd-max-triangles` (0: none) are
  skipped. Either case is reported in the table, not hidden. Pass the CoACD defaults back
  for a full-effort run.

Reach, both ways, per method (each part is the convex hull of its points):

* **out**: how far the parts reach outside the object: the largest distance to the mesh
  surface of points of the parts' boundaries (every hull vertex and area-weighted samples of
  the hull faces) that are not inside the mesh. Inside = generalized winding number > 0.5
  (exact for a closed, consistently oriented mesh; a sensible inside for the rest), computed
  with the fast first-order scheme of Barill et al. 2018 (far triangle clusters as dipoles).
* **in**: how far the object's surface is from the parts: the largest distance from mesh
  surface points (its vertices and area-weighted samples) to the union of the parts (0 inside
  a part): the Hausdorff distance the other way.

Both maxima are exact over the samples: a KD tree over dense samples of the target surface
gives an upper bound of each point's distance; exact point-to-triangle distances (trimesh
proximity) are computed in decreasing order of that bound until the bound falls below the best
exact value (or 1 µm). Distances are reported in mm and in % of the asset's bounding-box diagonal.

Times are wall clock on whatever the machine is doing; the three methods are not given the same
number of threads (mesa and V-HACD use several, CoACD one).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, cKDTree

ROOT = Path(__file__).resolve().parent.parent
SEED = 20261126
PART_SAMPLES = 20_000
MESH_SAMPLES = 40_000
# Distances below this are reported as 0 (a micrometre: far below any tolerance); it stops the
# exact search over points lying on the target surface.
FLOOR_M = 1e-6


def table_from_gltf(points: np.ndarray) -> np.ndarray:
    """mesa's table-aligned frame (no yaw): (X, Y, Z) -> (X, -Z, Y)."""
    return np.stack([points[:, 0], -points[:, 2], points[:, 1]], axis=1)


def hull_mesh(points: np.ndarray) -> trimesh.Trimesh | None:
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 4:
        return None
    try:
        hull = ConvexHull(points)
    except Exception:
        # A flat part (V-HACD gives some on thin walls) still covers its polygon: joggled.
        try:
            hull = ConvexHull(points, qhull_options="QJ")
        except Exception:
            return None
    faces = hull.simplices.copy()
    tri = points[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    inward = np.einsum("fk,fk->f", normals, hull.equations[:, :3]) < 0
    faces[inward] = faces[inward][:, ::-1]  # outward, as scipy's facet equations say
    return trimesh.Trimesh(points, faces, process=False)


def sample_surface(mesh: trimesh.Trimesh, count: int, rng: np.random.Generator) -> np.ndarray:
    areas = mesh.area_faces
    if areas.sum() <= 0 or count <= 0:
        return np.empty((0, 3))
    faces = rng.choice(len(areas), size=count, p=areas / areas.sum())
    tri = mesh.triangles[faces]
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])


def _exact_winding(points: np.ndarray, tri: np.ndarray, batch: int = 24) -> np.ndarray:
    """Winding number of each point over the triangles `tri` (T, 3, 3): van Oosterom-Strackee
    solid angles, summed."""
    out = np.empty(len(points))
    for start in range(0, len(points), batch):
        p = points[start : start + batch, None, None, :]
        abc = tri[None, :, :, :] - p  # (b, T, 3, 3)
        a, b, c = abc[:, :, 0], abc[:, :, 1], abc[:, :, 2]
        la, lb, lc = (np.sqrt(np.einsum("ptk,ptk->pt", x, x)) for x in (a, b, c))
        det = np.einsum("ptk,ptk->pt", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("ptk,ptk->pt", a, b) * lc
            + np.einsum("ptk,ptk->pt", b, c) * la
            + np.einsum("ptk,ptk->pt", c, a) * lb
        )
        out[start : start + batch] = (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)
    return out


class Winding:
    """Fast generalized winding numbers (Barill et al. 2018, first order): triangles grouped in
    clusters on a grid; a cluster farther than `FAR` times its radius counts as its dipole
    (area-weighted normal at its centroid), the others exactly. Inside = winding > 0.5: exact
    for a closed, consistently oriented mesh, a sensible inside for the rest."""

    FAR = 3.0

    def __init__(self, mesh: trimesh.Trimesh, per_cluster: int = 64):
        self.tri = np.asarray(mesh.triangles, dtype=np.float64)
        centroids = self.tri.mean(axis=1)
        lo, hi = centroids.min(0), centroids.max(0)
        cells = max(1, len(self.tri) // per_cluster)
        side = max(float((np.prod(np.maximum(hi - lo, 1e-12)) / cells) ** (1 / 3)), 1e-12)
        keys = np.floor((centroids - lo) / side).astype(np.int64)
        _, label = np.unique(keys, axis=0, return_inverse=True)
        label = label.ravel()
        order = np.argsort(label, kind="stable")
        bounds = np.flatnonzero(np.diff(label[order])) + 1
        self.members = np.split(order, bounds)
        area_vec = 0.5 * np.cross(self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0])
        area = np.linalg.norm(area_vec, axis=1)
        self.center = np.array(
            [
                (centroids[m] * area[m, None]).sum(0) / area[m].sum()
                if area[m].sum() > 0
                else centroids[m].mean(0)
                for m in self.members
            ]
        )
        self.dipole = np.array([area_vec[m].sum(0) for m in self.members])
        self.radius = np.array(
            [
                np.linalg.norm(self.tri[m].reshape(-1, 3) - c, axis=1).max()
                for m, c in zip(self.members, self.center)
            ]
        )

    def __call__(self, points: np.ndarray) -> np.ndarray:
        out = np.empty(len(points))
        for i, p in enumerate(points):
            d = self.center - p
            r = np.linalg.norm(d, axis=1)
            far = r > self.FAR * self.radius
            w = (np.einsum("kc,kc->k", self.dipole[far], d[far]) / r[far] ** 3).sum() / (
                4.0 * np.pi
            )
            near = np.flatnonzero(~far)
            if len(near):
                idx = np.concatenate([self.members[k] for k in near])
                w += _exact_winding(p[None, :], self.tri[idx])[0]
            out[i] = w
        return out


def max_outside_distance(
    points: np.ndarray,
    mesh: trimesh.Trimesh,
    mesh_cloud: cKDTree,
    winding: Winding,
    batch: int = 512,
) -> float:
    """Largest distance to `mesh`'s surface of `points` not inside it (exact over the points)."""
    if len(points) == 0:
        return 0.0
    upper, _ = mesh_cloud.query(points)
    order = np.argsort(-upper)
    best = 0.0
    for start in range(0, len(order), batch):
        idx = order[start : start + batch]
        if upper[idx[0]] <= max(best, FLOOR_M):
            break
        _, dist, _ = trimesh.proximity.closest_point(mesh, points[idx])
        farther = dist > max(best, FLOOR_M)
        if not farther.any():
            continue
        idx, dist = idx[farther], dist[farther]
        # The farthest first: the first one outside is the largest of the batch.
        for j in np.argsort(-dist):
            if dist[j] <= best:
                break
            if winding(points[idx[j]][None, :])[0] < 0.5:
                best = float(dist[j])
    return best


def max_distance_to_union(
    points: np.ndarray, hulls: list[trimesh.Trimesh], rng: np.random.Generator, batch: int = 1024
) -> float:
    """Largest distance of `points` to the union of the convex `hulls` (0 inside one)."""
    if not hulls:
        return float("inf")
    covered = np.zeros(len(points), dtype=bool)
    for h in hulls:
        normals, origins = h.face_normals, h.triangles[:, 0]
        offsets = np.einsum("fk,fk->f", normals, origins)
        todo = np.flatnonzero(~covered)
        if len(todo) == 0:
            break
        violation = (points[todo] @ normals.T - offsets).max(axis=1)
        covered[todo[violation <= 1e-9]] = True
    outside = points[~covered]
    if len(outside) == 0:
        return 0.0
    soup = trimesh.util.concatenate(hulls)
    cloud = cKDTree(np.vstack([soup.vertices, sample_surface(soup, 200_000, rng)]))
    upper, _ = cloud.query(outside)
    order = np.argsort(-upper)
    best = 0.0
    for start in range(0, len(order), batch):
        idx = order[start : start + batch]
        if upper[idx[0]] <= max(best, FLOOR_M):
            break
        _, dist, _ = trimesh.proximity.closest_point(soup, outside[idx])
        best = max(best, float(dist.max()))
    return best


def measure(parts: list[np.ndarray], mesh: trimesh.Trimesh, mesh_cloud: cKDTree,
            winding: Winding, mesh_points: np.ndarray, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    hulls = [h for h in (hull_mesh(p) for p in parts) if h is not None]
    if not hulls:
        return {"parts": len(parts), "out_m": float("nan"), "in_m": float("nan")}
    areas = np.array([h.area for h in hulls])
    per_part = np.maximum(8, np.round(PART_SAMPLES * areas / areas.sum()).astype(int))
    boundary = np.vstack(
        [h.vertices for h in hulls] + [sample_surface(h, n, rng) for h, n in zip(hulls, per_part)]
    )
    return {
        "parts": len(parts),
        "out_m": max_outside_distance(boundary, mesh, mesh_cloud, winding),
        "in_m": max_distance_to_union(mesh_points, hulls, rng),
    }


def run_vhacd(vertices: np.ndarray, faces: np.ndarray) -> tuple[list[np.ndarray], float]:
    import vhacdx

    started = time.perf_counter()
    hulls = vhacdx.compute_vhacd(vertices, faces.astype(np.uint32))
    return [np.asarray(v) for v, _ in hulls], time.perf_counter() - started


def _coacd_child(vertices, faces, options, queue):
    import coacd

    coacd.set_log_level("error")
    started = time.perf_counter()
    parts = coacd.run_coacd(coacd.Mesh(vertices, faces), seed=0, **options)
    queue.put(([np.asarray(v) for v, _ in parts], time.perf_counter() - started))


def run_coacd(vertices, faces, options: dict, timeout_s: float):
    queue = mp.get_context("fork").Queue()
    child = mp.get_context("fork").Process(
        target=_coacd_child, args=(vertices, faces, options, queue)
    )
    child.start()
    try:
        result = queue.get(timeout=timeout_s)
    except Exception:
        result = None
    child.join(timeout=5)
    if child.is_alive():
        child.kill()
        child.join()
    return result


def mesa_parts(mesa: Path, glb: Path, work: Path, config: Path | None) -> dict:
    dataset = work / "dataset"
    shutil.rmtree(dataset, ignore_errors=True)
    (dataset / "assets/library").mkdir(parents=True)
    if config is not None:
        shutil.copyfile(config, dataset / "mesa.toml")
    shutil.copyfile(glb, dataset / "assets/library" / glb.name)
    started = time.perf_counter()
    done = subprocess.run(
        [str(mesa), "assets", "--progress", "off", str(dataset)], capture_output=True, text=True
    )
    elapsed = time.perf_counter() - started
    if done.returncode != 0:
        raise RuntimeError(f"mesa assets {glb.name}: exit {done.returncode}: {done.stderr}")
    uid = glb.stem
    record = json.loads((dataset / "assets/index/assets.json").read_text())["assets"][uid]
    if not record.get("valid"):
        return {"valid": False, "reason_code": record.get("reason_code")}
    shapes = json.loads((dataset / record["shapes"]["file"]).read_text())
    return {
        "valid": True,
        "parts": [np.asarray(p["points_m"]) for p in shapes["parts"]],
        "decomposition": shapes["decomposition"],
        "warnings": record.get("warnings", []),
        "time_s": elapsed,
    }


def trimesh_bounds_check(glb: Path, mesh: trimesh.Trimesh) -> str:
    """Independent check of the frame: trimesh's own reading of the GLB, converted."""
    gltf = json.loads(glb.read_bytes()[20 : 20 + int.from_bytes(glb.read_bytes()[12:16], "little")])
    if "KHR_draco_mesh_compression" in gltf.get("extensionsRequired", []):
        return "trimesh cannot decode Draco: not checked"
    try:
        scene = trimesh.load(glb, force="scene")
        loaded = scene.to_geometry()
        if len(loaded.vertices) == 0:
            return "trimesh: no vertices"
    except Exception as e:  # Draco, meshopt, ...: trimesh cannot read every GLB mesa reads
        return f"trimesh cannot read it ({type(e).__name__})"
    verts = table_from_gltf(np.asarray(loaded.vertices))
    gap = np.abs(verts.min(0) - mesh.bounds[0]).max() + np.abs(verts.max(0) - mesh.bounds[1]).max()
    return f"bounds agree with trimesh to {gap * 1000:.3f} mm"


def fmt_reach(m: dict, diagonal: float) -> str:
    if m is None:
        return "–"
    return (
        f"{m['out_m'] * 1000:.2f} / {m['in_m'] * 1000:.2f} mm "
        f"({100 * m['out_m'] / diagonal:.2f} / {100 * m['in_m'] / diagonal:.2f} %)"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--glb-dir", type=Path, default=ROOT.parent / "shared/realdata/glb")
    parser.add_argument("--out", type=Path, default=ROOT / "target/bench-decomposition")
    parser.add_argument("--mesa", type=Path, default=ROOT / "target/release/mesa")
    parser.add_argument(
        "--table-mesh", type=Path, default=ROOT / "target/release/examples/table_mesh"
    )
    parser.add_argument("--coacd-timeout-s", type=float, default=45.0)
    parser.add_argument("--coacd-mcts-iterations", type=int, default=50)
    parser.add_argument("--coacd-mcts-nodes", type=int, default=10)
    parser.add_argument("--coacd-resolution", type=int, default=1000)
    parser.add_argument("--coacd-max-triangles", type=int, default=0)
    parser.add_argument("--only", nargs="*", help="GLB stems to run (default: all)")
    parser.add_argument(
        "--mesa-config", type=Path, help="a mesa.toml for the datasets (default: none)"
    )
    parser.add_argument(
        "--mesa-only", action="store_true", help="measure mesa's parts only (no V-HACD, CoACD)"
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    rows, skipped = [], []
    glbs = sorted(args.glb_dir.glob("*.glb"))
    if args.only:
        glbs = [g for g in glbs if g.stem in args.only]
    for glb in glbs:
        work = args.out / glb.stem
        work.mkdir(parents=True, exist_ok=True)
        ours = mesa_parts(args.mesa, glb, work, args.mesa_config)
        if not ours["valid"]:
            skipped.append((glb.name, ours["reason_code"]))
            print(f"{glb.name}: skipped, invalid for mesa ({ours['reason_code']})", flush=True)
            continue
        ply = work / "mesh.ply"
        subprocess.run([str(args.table_mesh), str(glb), str(ply)], check=True)
        mesh = trimesh.load(ply, process=False)
        frame_check = trimesh_bounds_check(glb, mesh)
        rng = np.random.default_rng(SEED)
        mesh_points = np.vstack([mesh.vertices, sample_surface(mesh, MESH_SAMPLES, rng)])
        mesh_cloud = cKDTree(np.vstack([mesh_points, sample_surface(mesh, 200_000, rng)]))
        winding = Winding(mesh)
        diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int32)

        row = {
            "file": glb.name,
            "triangles": len(mesh.faces),
            "diagonal_m": diagonal,
            "frame_check": frame_check,
        }
        started = time.perf_counter()
        row["mesa"] = measure(ours["parts"], mesh, mesh_cloud, winding, mesh_points, SEED)
        row["mesa"]["time_s"] = ours["time_s"]
        dec = ours["decomposition"]
        row["mesa"]["claimed_m"] = (
            dec.get("simplified", {}).get("reach_m")
            if dec.get("simplified")
            else dec.get("max_deviation_m")
        )
        row["mesa"]["method"] = dec["method"]
        row["mesa"]["part_budget"] = dec.get("part_budget")
        row["mesa"]["over_tolerance"] = dec.get("over_tolerance")
        row["mesa"]["max_parts"] = dec["max_parts"]
        row["mesa"]["reach_warnings"] = [w for w in ours["warnings"] if "outside" in w]

        if args.mesa_only:
            row["vhacd"] = {"skipped": "not run"}
        else:
            vh_parts, vh_time = run_vhacd(vertices, faces.astype(np.uint32))
            row["vhacd"] = measure(vh_parts, mesh, mesh_cloud, winding, mesh_points, SEED)
            row["vhacd"]["time_s"] = vh_time

        if args.mesa_only:
            row["coacd"] = {"skipped": "not run"}
        elif args.coacd_max_triangles and len(faces) > args.coacd_max_triangles:
            row["coacd"] = {"skipped": f"over {args.coacd_max_triangles} triangles"}
        else:
            options = {
                "mcts_iterations": args.coacd_mcts_iterations,
                "mcts_nodes": args.coacd_mcts_nodes,
                "resolution": args.coacd_resolution,
            }
            result = run_coacd(vertices, faces, options, args.coacd_timeout_s)
            if result is None:
                row["coacd"] = {"skipped": f"no result within {args.coacd_timeout_s:.0f} s"}
            else:
                co_parts, co_time = result
                row["coacd"] = measure(co_parts, mesh, mesh_cloud, winding, mesh_points, SEED)
                row["coacd"]["time_s"] = co_time
        rows.append(row)
        print(
            f"{glb.name}: {row['triangles']} triangles, measured in "
            f"{time.perf_counter() - started:.0f} s; {frame_check}; "
            + "; ".join(
                f"{k} {row[k].get('parts', '-')} parts {fmt_reach(row[k], diagonal)}"
                if "skipped" not in row[k]
                else f"{k} {row[k]['skipped']}"
                for k in ("mesa", "vhacd", "coacd")
            ),
            flush=True,
        )
        (args.out / "results.json").write_text(json.dumps({"rows": rows, "skipped": skipped},
                                                          indent=1))

    print()
    print(markdown_table(rows, skipped))
    return 0


def cell(m: dict, diagonal: float) -> str:
    if "skipped" in m:
        return m["skipped"]
    return (
        f"{m['parts']} · {m['out_m'] * 1000:.3g} / {m['in_m'] * 1000:.3g} mm "
        f"({100 * m['out_m'] / diagonal:.2g} / {100 * m['in_m'] / diagonal:.2g} %) · "
        f"{m['time_s']:.1f} s"
    )


def markdown_table(rows: list[dict], skipped: list[tuple[str, str]]) -> str:
    lines = [
        "| file | triangles | diagonal | mesa: parts · out / in · time | mesa claims |"
        " V-HACD | CoACD |",
        "|---|---:|---:|---|---:|---|---|",
    ]
    for r in sorted(rows, key=lambda r: -r["triangles"]):
        d = r["diagonal_m"]
        claimed = r["mesa"].get("claimed_m")
        lines.append(
            f"| {r['file']} | {r['triangles']} | {d:.3g} m | {cell(r['mesa'], d)} | "
            f"{'–' if claimed is None else f'{claimed * 1000:.3g} mm'} | "
            f"{cell(r['vhacd'], d)} | {cell(r['coacd'], d)} |"
        )
    if skipped:
        lines.append("")
        lines.append(
            "Skipped (invalid for mesa): "
            + ", ".join(f"{name} ({code})" for name, code in skipped)
            + "."
        )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
