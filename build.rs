// Records the git revision of the build (if any) for provenance in run summaries and reports.
fn main() {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let rev = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_default();
    println!("cargo:rustc-env=PROGMO_GIT_REVISION={rev}");
    // Where HEAD and the refs are: in a git worktree `.git` is a file, and a missing path would
    // make cargo rerun this script, and so rebuild the crate, on every build.
    // (the branch's own ref only: the shared refs folder changes with every commit of any worktree)
    let branch = git(&["symbolic-ref", "-q", "HEAD"]).unwrap_or_else(|| "refs".into());
    for what in ["HEAD", branch.as_str(), "packed-refs"] {
        let path =
            git(&["rev-parse", "--git-path", what]).unwrap_or_else(|| format!(".git/{what}"));
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
