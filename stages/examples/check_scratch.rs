use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use mesa_schemas::artifacts::{AssetIndexArtifact, ShapesArtifact};
use mesa_schemas::DatasetLayout;
use mesa_stages::check::*;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ds = Path::new(&args[1]);
    let which = &args[2];
    let index: AssetIndexArtifact = serde_json::from_str(&std::fs::read_to_string(ds.join("assets/index/assets.json")).unwrap()).unwrap();
    let mut shapes = BTreeMap::new();
    for (uid, r) in &index.assets {
        if let (Some(s), Some(g)) = (&r.shapes, &r.geometry) {
            let art: ShapesArtifact = serde_json::from_str(&std::fs::read_to_string(ds.join(&s.file)).unwrap()).unwrap();
            shapes.insert(uid.clone(), Arc::new(AssetShape::new(uid, &art, g).unwrap()));
        }
    }
    let tol = Tolerances::default();
    let mut files: Vec<_> = glob(ds, which);
    files.sort();
    let (mut pairs, mut coll, mut flo, mut viol, mut mt) = (0, 0, 0, 0, 0);
    let t0 = std::time::Instant::now();
    for f in &files {
        let layout: DatasetLayout = serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        let scene = PhysicsScene::from_layout(&layout, |o| shapes.get(&o.retrieved_uid).cloned().ok_or("no shape".to_string()));
        let fd = check_scene(&scene, &tol);
        let s = fd.to_schema(&scene);
        pairs += s.pairs_total; coll += s.collisions.len(); flo += s.floating.len(); viol += s.zone_violations.len(); mt += s.mesatask_rule_pairs;
        if !s.clean && args.len() > 3 {
            println!("{}: {}", f.display(), serde_json::to_string(&s).unwrap());
        }
    }
    println!("{} scenes, pairs {pairs} coll {coll} floating {flo} viol {viol} mesatask {mt} in {:?}", files.len(), t0.elapsed());
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
