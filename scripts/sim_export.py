#!/usr/bin/env python3
"""Loads scenes written by `mesa export` in a simulator and measures how still they stay.

Usage: sim_export.py mujoco|pybullet|usd SECONDS SCENE_DIR...   (each SCENE_DIR holds sim/export.json)
Output: JSON on standard output,
    {scene_dir: {"loaded": bool, "error": str|null, "bodies": [names],
                 "colliders": {instance: count}, "objects": {instance: {"moved_cm": float,
                 "fell": bool}}, "visuals": {instance: {...}}}}

"visuals" says what of each object's visual materials reached the simulator: MuJoCo the
model's texture and material counts ("ntex", "nmat") and per object its visual geoms (group
1, not colliding), those with a material, and those whose material has a texture and whose
mesh has texture coordinates; PyBullet per object its visual shapes and those PyBullet gave a
texture; USD per object its visual meshes, those with `primvars:st`, and the PNG files their
bound materials' shader graphs read (each must exist).

MuJoCo: sim/mjcf/scene.xml is loaded with `MjModel.from_xml_path`; every body's collision geoms
(group 3) are counted; the scene is stepped for SECONDS of simulated time at the file's
timestep. An object's displacement is the largest distance any vertex of its convex parts
(the OBJ files of sim/mjcf/meshes, body frame) moved; it fell when its centre of mass ended
more than 5 cm below the table top (z = 0).

PyBullet: sim/urdf/table.urdf is loaded with a fixed base, every object's URDF at its pose from
sim/urdf/scene.json with URDF_USE_INERTIA_FROM_FILE; the collision shapes of each base link are
counted; SECONDS at the step sim/urdf/scene.json gives ("timestep_s", the MJCF's; 1/240 s,
PyBullet's default, for a file without it); the same displacement measure (on the base frame
PyBullet reports).

USD (no simulation): sim/usd/scene.usda is opened with usd-core; per rigid body its instance,
mass, diagonal inertia and the count of its CollisionAPI meshes, the static colliders, and a
list of problems (up axis, metres per unit, PhysicsScene, MassAPI, MeshCollisionAPI with
convexHull, visual meshes each bound to a material, a textured material's graph reaching an
existing file through a UsdUVTexture read at the mesh's `st`). Also per object: the final
height of its centre of mass ("final_z_cm") and how far its origin drifted in the plane
("final_xy_offset_cm").
"""

import json
import os
import sys

import numpy as np


def obj_vertices(path):
    out = []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                out.append([float(v) for v in line.split()[1:4]])
    return np.asarray(out, dtype=float).reshape(-1, 3)


def part_points(mesh_dir, instance, count):
    pts = [obj_vertices(os.path.join(mesh_dir, f"{instance}.part_{k:03d}.obj")) for k in range(count)]
    return np.vstack(pts) if pts else np.zeros((1, 3))


def moved(local, p0, r0, p1, r1):
    a = local @ r0.T + p0
    b = local @ r1.T + p1
    return float(np.max(np.linalg.norm(b - a, axis=1)))


def run_mujoco(scene_dir, seconds):
    import mujoco

    manifest = json.load(open(os.path.join(scene_dir, "sim", "export.json")))
    xml = os.path.join(scene_dir, "sim", "mjcf", "scene.xml")
    try:
        model = mujoco.MjModel.from_xml_path(xml)
    except Exception as e:  # noqa: BLE001 - reported to the Rust test
        return {"loaded": False, "error": str(e)}
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = [model.body(i).name for i in range(1, model.nbody)]
    colliders = {}
    for g in range(model.ngeom):
        if model.geom_group[g] == 3 and model.geom_contype[g] != 0:
            name = model.body(model.geom_bodyid[g]).name
            colliders[name] = colliders.get(name, 0) + 1
    visuals = mujoco_visuals(model)
    mesh_dir = os.path.join(scene_dir, "sim", "mjcf", "meshes")
    start = {}
    for o in manifest["objects"]:
        b = model.body(o["instance"]).id
        local = part_points(mesh_dir, o["instance"], o["collision_parts"])
        start[o["instance"]] = (b, local, data.xpos[b].copy(), data.xmat[b].reshape(3, 3).copy())
    steps = int(round(seconds / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
    objects, final_z, final_xy = {}, {}, {}
    for name, (b, local, p0, r0) in start.items():
        final_z[name] = 100.0 * float(data.xipos[b][2])
        final_xy[name] = 100.0 * float(np.linalg.norm(data.xpos[b][:2] - p0[:2]))
        p1, r1 = data.xpos[b].copy(), data.xmat[b].reshape(3, 3).copy()
        objects[name] = {
            "moved_cm": 100.0 * moved(local, p0, r0, p1, r1),
            "fell": bool(data.xipos[b][2] < -0.05),
        }
    return {
        "loaded": True,
        "error": None,
        "bodies": bodies,
        "colliders": colliders,
        "objects": objects,
        "final_z_cm": final_z,
        "final_xy_offset_cm": final_xy,
        "visuals": visuals,
    }


def mujoco_visuals(model):
    """What of the visual materials MuJoCo compiled: counts per body of its visual geoms."""
    import mujoco

    rgb = int(mujoco.mjtTextureRole.mjTEXROLE_RGB)
    per_body = {}
    for g in range(model.ngeom):
        if model.geom_group[g] != 1 or model.geom_contype[g] != 0:
            continue
        name = model.body(model.geom_bodyid[g]).name
        v = per_body.setdefault(name, {"geoms": 0, "with_material": 0, "textured": 0})
        v["geoms"] += 1
        mat = int(model.geom_matid[g])
        if mat < 0:
            continue
        v["with_material"] += 1
        mesh = int(model.geom_dataid[g])
        texture = int(model.mat_texid[mat][rgb])
        if texture >= 0 and mesh >= 0 and model.mesh_texcoordnum[mesh] > 0:
            v["textured"] += 1
    return {"ntex": int(model.ntex), "nmat": int(model.nmat), "bodies": per_body}


def quat_matrix(q):
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def run_pybullet(scene_dir, seconds):
    import pybullet as p

    manifest = json.load(open(os.path.join(scene_dir, "sim", "export.json")))
    urdf_dir = os.path.join(scene_dir, "sim", "urdf")
    scene = json.load(open(os.path.join(urdf_dir, "scene.json")))
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        # The step the scene was exported for (PyBullet's default is 1/240 s).
        dt = float(scene.get("timestep_s") or 1.0 / 240.0)
        p.setTimeStep(dt, physicsClientId=client)
        t = scene.get("table")
        if t:
            p.loadURDF(
                os.path.join(urdf_dir, t["urdf"]),
                t["position_m"],
                t["orientation_xyzw"],
                useFixedBase=True,
                physicsClientId=client,
            )
        mesh_dir = os.path.join(scene_dir, "sim", "mjcf", "meshes")
        parts = {o["instance"]: o["collision_parts"] for o in manifest["objects"]}
        bodies, colliders, start, visuals = [], {}, {}, {}
        for o in scene["objects"]:
            try:
                body = p.loadURDF(
                    os.path.join(urdf_dir, o["urdf"]),
                    o["position_m"],
                    o["orientation_xyzw"],
                    flags=p.URDF_USE_INERTIA_FROM_FILE,
                    physicsClientId=client,
                )
            except Exception as e:  # noqa: BLE001 - reported to the Rust test
                return {"loaded": False, "error": f"{o['urdf']}: {e}"}
            name = p.getBodyInfo(body, physicsClientId=client)[1].decode()
            bodies.append(name)
            shapes = p.getVisualShapeData(
                body, flags=p.VISUAL_SHAPE_DATA_TEXTURE_UNIQUE_IDS, physicsClientId=client
            )
            visuals[name] = {
                "shapes": len(shapes),
                "textured": sum(1 for s in shapes if len(s) > 8 and s[8] >= 0),
            }
            colliders[name] = len(p.getCollisionShapeData(body, -1, physicsClientId=client))
            # The parts' points in the world, then in the base (inertial) frame PyBullet
            # reports, so the comparison does not depend on where that frame sits.
            local = part_points(mesh_dir, o["instance"], parts[o["instance"]])
            world = local @ quat_matrix(o["orientation_xyzw"]).T + np.asarray(o["position_m"])
            pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
            r0 = quat_matrix(orn)
            in_base = (world - np.asarray(pos)) @ r0
            start[o["instance"]] = (body, in_base, np.asarray(pos), r0)
        for _ in range(int(round(seconds / dt))):
            p.stepSimulation(physicsClientId=client)
        objects, final_z, final_xy = {}, {}, {}
        for name, (body, local, p0, r0) in start.items():
            pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
            p1, r1 = np.asarray(pos), quat_matrix(orn)
            objects[name] = {"moved_cm": 100.0 * moved(local, p0, r0, p1, r1), "fell": bool(p1[2] < -0.05)}
            final_z[name] = 100.0 * float(p1[2])
            final_xy[name] = 100.0 * float(np.linalg.norm(p1[:2] - p0[:2]))
        return {
            "loaded": True,
            "error": None,
            "bodies": bodies,
            "colliders": colliders,
            "objects": objects,
            "final_z_cm": final_z,
            "final_xy_offset_cm": final_xy,
            "visuals": visuals,
        }
    finally:
        p.disconnect(physicsClientId=client)


def run_usd(scene_dir, seconds):
    """Opens sim/usd/scene.usda with usd-core and reads back what the physics schemas say."""
    del seconds
    from pxr import Usd, UsdGeom, UsdPhysics

    path = os.path.join(scene_dir, "sim", "usd", "scene.usda")
    stage = Usd.Stage.Open(path)
    if stage is None:
        return {"loaded": False, "error": f"{path}: usd-core cannot open it"}
    problems = []
    if UsdGeom.GetStageUpAxis(stage) != UsdGeom.Tokens.z:
        problems.append("upAxis is not Z")
    if UsdGeom.GetStageMetersPerUnit(stage) != 1.0:
        problems.append("metersPerUnit is not 1")
    if not any(p.IsA(UsdPhysics.Scene) for p in stage.Traverse()):
        problems.append("no PhysicsScene")
    bodies, colliders, masses, inertias, statics, visuals = [], {}, {}, {}, 0, {}
    for prim in stage.Traverse():
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            instance = prim.GetAttribute("mesa:instance").Get()
            bodies.append(instance)
            if not prim.HasAPI(UsdPhysics.MassAPI):
                problems.append(f"{instance}: no MassAPI")
            mass_api = UsdPhysics.MassAPI(prim)
            masses[instance] = float(mass_api.GetMassAttr().Get())
            inertias[instance] = [float(v) for v in mass_api.GetDiagonalInertiaAttr().Get()]
            n = 0
            for child in Usd.PrimRange(prim):
                if child.HasAPI(UsdPhysics.CollisionAPI):
                    if not child.HasAPI(UsdPhysics.MeshCollisionAPI):
                        problems.append(f"{child.GetPath()}: no MeshCollisionAPI")
                    approx = UsdPhysics.MeshCollisionAPI(child).GetApproximationAttr().Get()
                    if approx != UsdPhysics.Tokens.convexHull:
                        problems.append(f"{child.GetPath()}: approximation {approx}")
                    n += 1
            colliders[instance] = n
            visuals[instance] = usd_visual(prim.GetChild("visual"), instance, problems)
        elif prim.HasAPI(UsdPhysics.CollisionAPI) and not any(
            a.HasAPI(UsdPhysics.RigidBodyAPI) for a in [prim.GetParent()]
        ):
            statics += 1
    return {
        "loaded": True,
        "error": None,
        "bodies": bodies,
        "colliders": colliders,
        "masses": masses,
        "inertias": inertias,
        "static_colliders": statics,
        "problems": problems,
        "visuals": visuals,
    }


def usd_visual(visual, instance, problems):
    """An object's visual meshes: each bound to a UsdPreviewSurface; a textured one's
    diffuseColor fed by a UsdUVTexture whose file exists and whose st is read from the mesh's
    `st` primvar by a UsdPrimvarReader_float2."""
    from pxr import UsdGeom, UsdShade

    out = {"meshes": 0, "with_st": 0, "textured": 0, "files": []}
    meshes = [c for c in visual.GetChildren() if c.IsA(UsdGeom.Mesh)] if visual else []
    if not meshes:
        problems.append(f"{instance}: no visual mesh")
    for mesh in meshes:
        out["meshes"] += 1
        where = str(mesh.GetPath())
        st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
        points = len(UsdGeom.Mesh(mesh).GetPointsAttr().Get() or [])
        if st and st.HasValue():
            values = st.Get()
            expected = points if st.GetInterpolation() == "vertex" else None
            if expected is not None and len(values) != expected:
                problems.append(f"{where}: {len(values)} st values for {points} points")
            out["with_st"] += 1
        material, _ = UsdShade.MaterialBindingAPI(mesh).ComputeBoundMaterial()
        if not material:
            problems.append(f"{where}: no bound material")
            continue
        surface = material.ComputeSurfaceSource()[0]
        if not surface or surface.GetIdAttr().Get() != "UsdPreviewSurface":
            problems.append(f"{where}: its material has no UsdPreviewSurface")
            continue
        diffuse = surface.GetInput("diffuseColor")
        if not (diffuse and diffuse.HasConnectedSource()):
            continue
        texture = UsdShade.Shader(diffuse.GetConnectedSources()[0][0].source.GetPrim())
        if texture.GetIdAttr().Get() != "UsdUVTexture":
            problems.append(f"{where}: diffuseColor fed by {texture.GetIdAttr().Get()}")
            continue
        file = texture.GetInput("file").Get()
        path = file.resolvedPath if file is not None else ""
        if not path or not os.path.isfile(path):
            problems.append(f"{where}: texture file {file} does not resolve to a file")
            continue
        st_input = texture.GetInput("st")
        reader = (
            UsdShade.Shader(st_input.GetConnectedSources()[0][0].source.GetPrim())
            if st_input and st_input.HasConnectedSource()
            else None
        )
        if not reader or reader.GetIdAttr().Get() != "UsdPrimvarReader_float2":
            problems.append(f"{where}: the texture's st is not read by a UsdPrimvarReader_float2")
            continue
        varname = reader.GetInput("varname").Get()
        if varname != "st" or not (st and st.HasValue()):
            problems.append(f"{where}: the texture reads primvar {varname!r}, which the mesh lacks")
            continue
        out["textured"] += 1
        out["files"].append(os.path.relpath(path, os.path.dirname(os.path.dirname(os.path.dirname(path)))))
    out["files"] = sorted(set(out["files"]))
    return out


def main():
    sim, seconds, dirs = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
    runner = {"mujoco": run_mujoco, "pybullet": run_pybullet, "usd": run_usd}[sim]
    # The simulators print banners from C (pybullet's build time): standard output is the
    # JSON alone, everything else goes to standard error.
    sys.stdout.flush()
    out = os.dup(1)
    os.dup2(2, 1)
    result = json.dumps({d: runner(d, seconds) for d in dirs})
    os.write(out, result.encode())


if __name__ == "__main__":
    main()
