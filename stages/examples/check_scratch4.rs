//! scratch
use parry3d::math::{Isometry, Point};
use parry3d::shape::ConvexPolyhedron;
fn main() {
    for scale in [1.0f64, 100.0, 1000.0] { run(scale); }
}
fn run(scale: f64) {
    println!("scale {scale}");
    let pts: Vec<[f64;3]> = vec![[0.006257378496229649, -0.039507534354925156, 0.052000001072883606], [0.006257378496229649, -0.039507534354925156, 0.10000000149011612], [0.01725163869559765, -0.033858247101306915, 0.052000001072883606], [0.0, -0.03799999877810478, 0.052000001072883606], [0.01725163869559765, -0.033858247101306915, 0.10000000149011612], [0.0, -0.03999999910593033, 0.10000000149011612], [0.0, -0.03999999910593033, 0.052000001072883606], [0.012360679917037487, -0.03804226219654083, 0.052000001072883606], [0.012360679917037487, -0.03804226219654083, 0.10000000149011612], [0.0, -0.03799999877810478, 0.10000000149011612], [0.01725163869559765, -0.03601635992527008, 0.10000000149011612], [0.01725163869559765, -0.03601635992527008, 0.052000001072883606]];
    let q = [0.007981511298567057, -0.03772661338249842, 0.10000000149011612 - 0.001];
    let p32: Vec<Point<f32>> = pts.iter().map(|p| Point::new((p[0]*scale) as f32, (p[1]*scale) as f32, (p[2]*scale) as f32)).collect();
    let q = q.map(|v| v * scale);
    let poly = ConvexPolyhedron::from_convex_hull(&p32).unwrap();
    let e = 1e-4f32 * scale as f32;
    let cube = parry3d::shape::Cuboid::new(parry3d::math::Vector::new(e, e, e));
    let pos2 = Isometry::translation(q[0] as f32, q[1] as f32, q[2] as f32);
    let id = Isometry::identity();
    println!("intersection_test {:?}", parry3d::query::intersection_test(&id, &poly, &pos2, &cube));
    println!("contact pred 0 {:?}", parry3d::query::contact(&id, &poly, &pos2, &cube, 0.0).map(|c| c.map(|c| c.dist)));
    println!("contact pred 1 {:?}", parry3d::query::contact(&id, &poly, &pos2, &cube, 1.0).map(|c| c.map(|c| c.dist)));
    println!("contact pred MAX {:?}", parry3d::query::contact(&id, &poly, &pos2, &cube, f32::MAX).map(|c| c.map(|c| c.dist)));
    println!("distance {:?}", parry3d::query::distance(&id, &poly, &pos2, &cube));
    println!("poly points {:?}", poly.points()); let (hp, ht) = parry3d::transformation::try_convex_hull(&p32).unwrap(); println!("hull {} pts {} tris", hp.len(), ht.len());
    use parry3d::query::PointQuery;
    println!("contains {}", poly.contains_point(&id, &Point::new(q[0] as f32, q[1] as f32, q[2] as f32)));
}
#[allow(dead_code)]
fn unused() {}
