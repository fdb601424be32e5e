//! scratch
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use mesa_schemas::DatasetLayout;
use mesa_stages::check::*;
use mesa_stages::assets::{index_asset, AssetsConfig};
use mesa_stages::annotations::Annotations;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ds = Path::new(&args[1]);
    let which = &args[2];
    let mut config = AssetsConfig::default();
    config.vhacd_resolution = std::env::var("RES").ok().map(|v| v.parse().unwrap()).unwrap_or(64);
    config.vhacd_concavity = std::env::var("CONC").ok().map(|v| v.parse().unwrap()).unwrap_or(0.01);
    config.vhacd_max_parts = std::env::var("PARTS").ok().map(|v| v.parse().unwrap()).unwrap_or(32); config.decomposition_max_parts = std::env::var("APARTS").ok().map(|v| v.parse().unwrap()).unwrap_or(128); config.decomposition_tolerance_m = std::env::var("ATOL").ok().map(|v| v.parse().unwrap()).unwrap_or(0.001);
    let ann = Annotations::read(&ds.join("assets/annotations.json")).unwrap();
    let mut shapes = BTreeMap::new();
    let t0 = std::time::Instant::now();
    let mut nparts = 0;
    let mut files: Vec<_> = glob(ds, which);
    files.sort();
    let mut used = std::collections::BTreeSet::new();
    for f in &files {
        let layout: DatasetLayout = serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        for o in &layout.objects { used.insert(o.retrieved_uid.clone()); }
    }
    for uid in &used {
        let bytes = std::fs::read(ds.join(format!("assets/library/{uid}.glb"))).unwrap();
        let idx = index_asset(uid, "x", &bytes, ann.get(uid), &config);
        let sh = idx.shapes.unwrap();
        nparts += sh.parts.len();
        if std::env::var("SHOW").is_ok() { println!("{uid} {:?} parts {} {:?}", ann.get(uid).and_then(|a| a.category.clone()), sh.parts.len(), sh.decomposition); }
        shapes.insert(uid.clone(), Arc::new(AssetShape::new(uid, &sh, idx.geometry.as_ref().unwrap()).unwrap()));
    }
    println!("indexed {} assets, {} parts in {:?}", used.len(), nparts, t0.elapsed());
    let tol = Tolerances::default();
    let (mut pairs, mut coll, mut flo, mut viol) = (0, 0, 0, 0);
    let mut maxd: f64 = 0.0;
    let t0 = std::time::Instant::now();
    for f in &files {
        let layout: DatasetLayout = serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        let scene = PhysicsScene::from_layout(&layout, |o| shapes.get(&o.retrieved_uid).cloned().ok_or("no shape".to_string()));
        if let Ok(dbg) = std::env::var("FALLDBG") {
            let (sc, inst) = dbg.split_once(' ').unwrap();
            if f.to_string_lossy().contains(sc) {
                let i = scene.objects.iter().position(|o| o.instance == inst).unwrap();
                let b = scene.objects[i].body.as_ref().unwrap();
                let j0 = scene.objects.iter().position(|o| o.instance == std::env::var("OTHER").unwrap()).unwrap();
                let f0 = scene.objects[j0].body.as_ref().unwrap();
                for (pi, hm) in b.hulls.iter().enumerate() { for (pj, hf) in f0.hulls.iter().enumerate() {
                    if !hm.bounds.overlaps_xy(&hf.bounds, 0.0) { continue; }
                    let p = mesa_stages::check::geometry::proximity(hm, hf);
                    let r: Vec<_> = [0.0005, 0.001, 0.002].iter().map(|r| mesa_stages::check::geometry::fall_distance(hm, hf, *r, 0.03)).collect();
                    println!("part {pi} x {pj}: prox {:.5} n {:?} falls {:?} zrange m {:.4}-{:.4} f {:.4}-{:.4}", p.signed_distance_m, p.normal.map(|v| (v*100.0).round()/100.0), r, hm.bounds.min[2], hm.bounds.max[2], hf.bounds.min[2], hf.bounds.max[2]);
                }}
                for (j, o) in scene.objects.iter().enumerate() {
                    if j == i { continue; }
                    let ob = o.body.as_ref().unwrap();
                    for raise in [0.0005, 0.001, 0.002, 0.004] {
                        let (g, over) = fall_of(b, std::iter::once((j, ob)), raise);
                        if over != Support::Table { println!("{} raise {raise}: gap {g} over {:?}", o.instance, over); }
                    }
                }
            }
        }
        let fd = check_scene(&scene, &tol);
        let s = fd.to_schema(&scene);
        if std::env::var("SETTLE").is_ok() {
            let gopts = mesa_stages::graph::GraphOptions::default();
            let containers = mesa_stages::graph::keyword_containers(&mesa_stages::graph::GraphScene::from_dataset(&layout), &gopts);
            let cfg = CheckConfig::default();
            let sc = check_layout(CheckedLayout { scene_id: "x", file: "coarse/layout.json", sha256: "", layout: &layout }, |o| shapes.get(&o.retrieved_uid).cloned().ok_or("no shape".to_string()), &containers, &gopts, &cfg, true);
            let rep = sc.artifact.settle.as_ref().unwrap();
            let recheck = sc.settled.as_ref().map(|l| { let sc2 = PhysicsScene::from_layout(l, |o| shapes.get(&o.retrieved_uid).cloned().ok_or("no shape".to_string())); check_scene(&sc2, &tol).clean() });
            println!("{} {:?} rounds {} median {:.2} max {:.2} recheck {:?} {}", f.display(), rep.status, rep.iterations, rep.median_displacement_cm, rep.max_displacement_cm, recheck, rep.reason.clone().unwrap_or_default());
        }
        pairs += s.pairs_total; coll += s.collisions.len(); flo += s.floating.len(); viol += s.zone_violations.len();
        for c in &s.collisions { maxd = maxd.max(c.depth_mm); }
        if !s.clean && args.len() > 3 {
            println!("{}: {}", f.display(), serde_json::to_string(&s).unwrap());
        }
    }
    println!("{} scenes, pairs {pairs} coll {coll} (max {maxd} mm) floating {flo} viol {viol} in {:?}", files.len(), t0.elapsed());
}

fn glob(ds: &Path, which: &str) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for t in std::fs::read_dir(ds.join("scenes")).unwrap() {
        for s in std::fs::read_dir(t.unwrap().path()).unwrap() {
            let p = s.unwrap().path().join(which);
            if p.exists() { out.push(p); }
        }
    }
    out
}
