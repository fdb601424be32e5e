//! The table, its sink, the floor and the wall, as meshes in the table frame (metres).

use std::sync::Arc;

use super::scene::{Table, TableBase, TableType, TopFinish};
use super::textures;
use crate::mesh::{Affine3, TriMesh};
use crate::raster::{srgb_u8_to_linear, SurfaceMaterial};

/// A piece of the room.
#[derive(Debug, Clone)]
pub(crate) struct RoomPart {
    /// Triangles in the table frame.
    pub mesh: TriMesh,
    pub material: SurfaceMaterial,
    /// Whether it belongs to the table (the support instance) rather than the background.
    pub is_table: bool,
}

fn linear(srgb: [u8; 3]) -> [f32; 3] {
    srgb.map(srgb_u8_to_linear)
}

/// A box spanning `min..max` (table frame).
fn span_box(min: [f64; 3], max: [f64; 3]) -> TriMesh {
    let size = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
    let centre = [
        (min[0] + max[0]) / 2.0,
        (min[1] + max[1]) / 2.0,
        (min[2] + max[2]) / 2.0,
    ];
    TriMesh::cuboid(size).transformed(&Affine3::from_translation(centre))
}

/// Texture coordinates tiling every `tile_m` metres, projected along the axis the normal
/// points most along.
fn tile_uvs(mesh: &mut TriMesh, tile_m: f64) {
    mesh.uvs = mesh
        .positions
        .iter()
        .zip(&mesh.normals)
        .map(|(p, n)| {
            let (a, b) = if n[2].abs() >= n[0].abs() && n[2].abs() >= n[1].abs() {
                (p[0], p[1])
            } else if n[1].abs() >= n[0].abs() {
                (p[0], p[2])
            } else {
                (p[1], p[2])
            };
            [(a as f64 / tile_m) as f32, (-b as f64 / tile_m) as f32]
        })
        .collect();
}

/// The room around and under the table.
pub(crate) fn build(table: &Table) -> Vec<RoomPart> {
    let (w, d, h, t) = (
        table.width_m,
        table.depth_m,
        table.height_m,
        table.thickness_m,
    );
    let mut parts = Vec::new();

    // The top, with a hole for the basin when there is a sink.
    let top_material = match &table.finish {
        TopFinish::Wood { light, dark, salt } => SurfaceMaterial {
            base_color: [1.0; 3],
            texture: Some(Arc::new(textures::wood(*light, *dark, *salt))),
            roughness: 0.45,
        },
        TopFinish::Stone { base, vein, salt } => SurfaceMaterial {
            base_color: [1.0; 3],
            texture: Some(Arc::new(textures::stone(*base, *vein, *salt))),
            roughness: 0.25,
        },
        TopFinish::Laminate(c) => SurfaceMaterial::plain(linear(*c), 0.35),
    };
    let mut top = TriMesh::default();
    match &table.sink {
        None => top.append(&span_box([0.0, 0.0, -t], [w, d, 0.0])),
        Some(sink) => {
            let [x0, x1, y0, y1] = sink.basin_m;
            top.append(&span_box([0.0, 0.0, -t], [x0, d, 0.0]));
            top.append(&span_box([x1, 0.0, -t], [w, d, 0.0]));
            top.append(&span_box([x0, 0.0, -t], [x1, y0, 0.0]));
            top.append(&span_box([x0, y1, -t], [x1, d, 0.0]));
        }
    }
    tile_uvs(&mut top, 0.6);
    parts.push(RoomPart {
        mesh: top,
        material: top_material,
        is_table: true,
    });

    // What holds it up.
    let base_material = SurfaceMaterial::plain(linear(table.base_srgb), 0.5);
    let mut base = TriMesh::default();
    match table.base {
        TableBase::Legs => {
            let (leg, inset) = (0.045, 0.04);
            for (x, y) in [
                (inset, inset),
                (w - inset - leg, inset),
                (inset, d - inset - leg),
                (w - inset - leg, d - inset - leg),
            ] {
                base.append(&span_box([x, y, -h], [x + leg, y + leg, -t]));
            }
            // An apron under the top.
            base.append(&span_box(
                [inset, inset, -t - 0.08],
                [w - inset, inset + 0.02, -t],
            ));
        }
        TableBase::Cabinet => {
            base.append(&span_box([0.01, 0.02, -h + 0.08], [w - 0.01, d, -t]));
            base.append(&span_box([0.04, 0.05, -h], [w - 0.04, d, -h + 0.08]));
            // Door gaps as dark strips on the front.
            let doors = ((w / 0.5).round() as usize).max(1);
            for k in 1..doors {
                let x = w * k as f64 / doors as f64;
                base.append(&span_box(
                    [x - 0.002, 0.017, -h + 0.1],
                    [x + 0.002, 0.02, -t - 0.02],
                ));
            }
        }
    }
    parts.push(RoomPart {
        mesh: base,
        material: base_material,
        is_table: true,
    });

    if let Some(sink) = &table.sink {
        let [x0, x1, y0, y1] = sink.basin_m;
        // An open box seen from inside: the cuboid turned inside out, without its top.
        let bowl = span_box([x0, y0, -sink.depth_m], [x1, y1, 0.0]);
        let mut inside = TriMesh::default();
        for tri in &bowl.triangles {
            let n = bowl.normals[tri[0] as usize];
            if n[2] > 0.5 {
                continue;
            }
            let base_index = inside.positions.len() as u32;
            for &v in &[tri[0], tri[2], tri[1]] {
                inside.positions.push(bowl.positions[v as usize]);
                inside.normals.push(bowl.normals[v as usize].map(|c| -c));
            }
            inside
                .triangles
                .push([base_index, base_index + 1, base_index + 2]);
        }
        parts.push(RoomPart {
            mesh: inside,
            material: SurfaceMaterial::plain(linear([240, 240, 238]), 0.15),
            is_table: true,
        });
        // A faucet behind the basin.
        let cx = (x0 + x1) / 2.0;
        let fy = (y1 + sink.zone_m[3]) / 2.0;
        let mut faucet = TriMesh::cylinder(0.022, 0.05, 20).transformed(&Affine3::from_trs(
            [cx, fy, 0.0],
            crate::mesh::quat_from_axis_angle([1.0, 0.0, 0.0], std::f64::consts::FRAC_PI_2),
            [1.0; 3],
        ));
        // The spout arcs forward over the basin (an arc in the y-z plane).
        let spout = TriMesh::tube_arc(0.07, 0.011, 0.0, std::f64::consts::PI * 0.95, 20, 12)
            .transformed(&Affine3 {
                linear: [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                translation: [cx, fy - 0.07, 0.1],
            });
        faucet.append(&spout);
        faucet.append(
            &TriMesh::cylinder(0.011, 0.06, 16).transformed(&Affine3::from_trs(
                [cx, fy, 0.04],
                crate::mesh::quat_from_axis_angle([1.0, 0.0, 0.0], std::f64::consts::FRAC_PI_2),
                [1.0; 3],
            )),
        );
        parts.push(RoomPart {
            mesh: faucet,
            material: SurfaceMaterial::plain(linear([214, 216, 220]), 0.1),
            is_table: true,
        });
    }

    // Floor and wall (background).
    let far = 4.0;
    let wall_y = d + table.wall_gap_m;
    let mut floor = span_box([-far, -far - 2.0, -h - 0.02], [w + far, wall_y, -h]);
    tile_uvs(&mut floor, 1.0);
    let floor_texture = match table.kind {
        TableType::KitchenCounter | TableType::BathroomVanity => {
            textures::tiles([214, 210, 202], [160, 156, 150])
        }
        _ => textures::wood([176, 136, 100], [140, 100, 70], 77),
    };
    parts.push(RoomPart {
        mesh: floor,
        material: SurfaceMaterial {
            base_color: [1.0; 3],
            texture: Some(Arc::new(floor_texture)),
            roughness: 0.6,
        },
        is_table: false,
    });
    let mut wall = span_box([-far, wall_y, -h], [w + far, wall_y + 0.05, 3.0 - h]);
    let wall_tile = match table.kind {
        TableType::KitchenCounter | TableType::BathroomVanity => 0.4,
        _ => 1.5,
    };
    tile_uvs(&mut wall, wall_tile);
    let wall_texture = match table.kind {
        TableType::KitchenCounter | TableType::BathroomVanity => {
            textures::tiles([234, 234, 230], [200, 200, 196])
        }
        _ => textures::plaster([228, 224, 214]),
    };
    parts.push(RoomPart {
        mesh: wall,
        material: SurfaceMaterial {
            base_color: [1.0; 3],
            texture: Some(Arc::new(wall_texture)),
            roughness: 0.9,
        },
        is_table: false,
    });
    if matches!(
        table.kind,
        TableType::DressingTable | TableType::BathroomVanity
    ) {
        // A mirror on the wall above the table.
        let mirror = span_box([w * 0.2, wall_y - 0.01, 0.25], [w * 0.8, wall_y, 1.0]);
        parts.push(RoomPart {
            mesh: mirror,
            material: SurfaceMaterial::plain(linear([176, 190, 198]), 0.05),
            is_table: false,
        });
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::scene::{make_table, TableType};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_table_top_is_the_placement_zone_at_z_0() {
        for kind in TableType::ALL {
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let table = make_table(kind, &mut rng);
            let parts = build(&table);
            let top = parts[0].mesh.bounds().expect("top");
            assert!((top.min[0]).abs() < 1e-6 && (top.max[0] - table.width_m).abs() < 1e-6);
            assert!((top.min[1]).abs() < 1e-6 && (top.max[1] - table.depth_m).abs() < 1e-6);
            assert!(top.max[2].abs() < 1e-6);
            for part in &parts {
                part.mesh.check().expect("valid room mesh");
                if !part.is_table {
                    continue;
                }
                // Nothing of the table rises above the top, except the faucet inside the
                // restricted zone.
                let b = part.mesh.bounds().expect("bounds");
                if b.max[2] > 1e-6 {
                    let zone = table.sink.expect("only a sink's faucet rises").zone_m;
                    assert!(
                        b.min[0] >= zone[0]
                            && b.max[0] <= zone[1]
                            && b.min[1] >= zone[2]
                            && b.max[1] <= zone[3],
                        "{b:?} {zone:?}"
                    );
                }
            }
        }
    }
}
