//! Writes the synthetic benchmark scene (1024×1024, 15 boxes on a table) as a scene's
//! `input/` folder: `cargo run --release -p mesa-stages --example synthetic_scene -- DIR`.

use mesa_stages::lift::synthetic::SyntheticScene;

fn main() -> std::io::Result<()> {
    let Some(dir) = std::env::args_os().nth(1) else {
        eprintln!("usage: synthetic_scene DIR");
        std::process::exit(2);
    };
    SyntheticScene::default().write(std::path::Path::new(&dir))
}
