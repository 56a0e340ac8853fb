//! Writes the planner benchmark's programs (see `benches/programs/gen.rs`) into a directory:
//! `cargo run --example planner_programs -- DIR`. `benches/planner_vs_linuxcnc.sh` plans
//! and runs them.

#[path = "../benches/programs/gen.rs"]
mod gen;

fn main() -> std::io::Result<()> {
    let dir = std::env::args_os()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| "target/planner-programs".into());
    std::fs::create_dir_all(&dir)?;
    for p in gen::all() {
        let path = dir.join(p.name);
        std::fs::write(&path, &p.text)?;
        println!(
            "{}\t{} lines\t{}",
            path.display(),
            p.text.lines().count(),
            p.title
        );
    }
    Ok(())
}
