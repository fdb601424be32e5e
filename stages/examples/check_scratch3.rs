//! scratch
use mesa_stages::assets::decompose::{decompose, AdaptiveParams};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&args[1]).unwrap();
    let mesh = mesa_stages::glb_read::read_glb(&bytes).unwrap();
    let pos: Vec<[f64;3]> = mesh.positions_m.iter().map(|p| mesa_stages::assets::table_aligned_from_gltf(*p, 0.0)).collect();
    let p = AdaptiveParams { tolerance_m: 0.001, max_parts: args.get(2).map(|v| v.parse().unwrap()).unwrap_or(128), min_size_m: 0.0002 };
    let t = std::time::Instant::now();
    let d = decompose(&pos, &mesh.triangles, &p).unwrap();
    println!("parts {} solid {} dev {} in {:?}", d.parts.len(), d.solid, d.max_deviation_m, t.elapsed());
    use parry3d::query::PointQuery;
    let polys: Vec<_> = d.parts.iter().filter_map(|p| parry3d::shape::ConvexPolyhedron::from_convex_hull(&p.points_m.iter().map(|q| parry3d::math::Point::new(q[0] as f32, q[1] as f32, q[2] as f32)).collect::<Vec<_>>())).collect();
    let mut worst = 0.0f32; let mut worst_p = [0.0;3];
    for t in &mesh.triangles {
        let c: [f64;3] = std::array::from_fn(|k| (pos[t[0] as usize][k]+pos[t[1] as usize][k]+pos[t[2] as usize][k])/3.0);
        let q = parry3d::math::Point::new(c[0] as f32, c[1] as f32, c[2] as f32);
        let _ = q;
        let ph = mesa_stages::check::geometry::Hull::new(&[c]).unwrap();
        let dmin = d.parts.iter().map(|p| mesa_stages::check::geometry::proximity(&mesa_stages::check::geometry::Hull::new(&p.points_m).unwrap(), &ph).signed_distance_m.max(0.0) as f32).fold(f32::INFINITY, f32::min);
        if dmin > worst { worst = dmin; worst_p = c; }
    }
    println!("uncovered surface: worst {worst} at {worst_p:?} ({} polys of {} parts)", polys.len(), d.parts.len());
    let ph = mesa_stages::check::geometry::Hull::new(&[worst_p]).unwrap();
    for p in &d.parts {
        let h = mesa_stages::check::geometry::Hull::new(&p.points_m).unwrap();
        if h.bounds.overlaps(&ph.bounds, 0.002) {
            let pr = mesa_stages::check::geometry::proximity(&h, &ph);
            println!("  part bounds {:?} {:?} prox {:?}", h.bounds.min, h.bounds.max, pr);
            let e = 1e-5;
            let mut cube = Vec::new();
            for dx in [-e, e] { for dy in [-e, e] { for dz in [-e, e] { cube.push([worst_p[0]+dx, worst_p[1]+dy, worst_p[2]+dz]); } } }
            let ch = mesa_stages::check::geometry::Hull::new(&cube).unwrap();
            println!("  cube prox {:?}  reversed {:?}", mesa_stages::check::geometry::proximity(&h, &ch), mesa_stages::check::geometry::proximity(&ch, &h));
        }
    }
    for part in &d.parts {
        let mut lo=[f64::INFINITY;3]; let mut hi=[f64::NEG_INFINITY;3];
        for q in &part.points_m { for k in 0..3 { lo[k]=lo[k].min(q[k]); hi[k]=hi[k].max(q[k]); } }
        if args.len() > 3 { println!("  {:?} {:?} n={} vol={:.2e}", lo.map(|v| (v*1000.0).round()), hi.map(|v| (v*1000.0).round()), part.points_m.len(), part.volume_m3); }
    }
}

#[allow(dead_code)]
fn coverage() {}
