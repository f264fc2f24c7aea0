//! MJCF `<include file="..."/>` as MuJoCo's reader expands it (XML reference, "include"): the
//! element, wherever it stands, is replaced by the children of the named file's `<mujoco>` root.
//! The path is relative to the main file's folder, also for an include inside an included file,
//! under the path rule of [`crate::input::resolve`]; a file is included at most once (which also
//! refuses cycles). The result is one composed [`Source`]: what the importer reports in an
//! included part (errors, unmodelled records) names that file and its line.

use crate::located::{SceneError, Source, Splice};
use roxmltree::Node;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

type R<T> = Result<T, SceneError>;

/// At most this many files are included into one model.
pub const MAX_INCLUDES: usize = 256;

/// What the expansion has gathered so far.
struct Composer {
    /// the main file's folder: every include path is relative to it
    dir: PathBuf,
    /// the files read so far (canonical), the main file first
    seen: Vec<PathBuf>,
    /// the pieces of the composed text, in order: (file, byte range in that file's text)
    pieces: Vec<(Arc<Source>, Range<usize>)>,
    /// bytes composed so far (bounded by [`crate::input::ROBOT_LIMIT`])
    total: usize,
}

/// `src` with every `<include>` expanded, or None when it has none.
pub(crate) fn expand(src: &Source) -> R<Option<Source>> {
    if !src.text.contains("<include") {
        return Ok(None);
    }
    let main = Arc::new(src.clone());
    let doc = super::parse_xml(&main)?;
    if !doc.descendants().any(|n| n.has_tag_name("include")) {
        return Ok(None);
    }
    let dir = src.file.parent().unwrap_or(Path::new(".")).to_path_buf();
    let first = std::fs::canonicalize(&src.file).unwrap_or_else(|_| src.file.clone());
    let mut c = Composer {
        dir,
        seen: vec![first],
        pieces: vec![],
        total: 0,
    };
    c.file(&main, &doc, 0..src.text.len())?;
    let mut text = String::with_capacity(c.total);
    let mut spliced = Vec::with_capacity(c.pieces.len());
    for (source, r) in c.pieces {
        let start = text.len();
        text.push_str(&source.text[r.clone()]);
        spliced.push(Splice {
            range: start..text.len(),
            source,
            offset: r.start,
        });
    }
    Ok(Some(Source {
        file: src.file.clone(),
        text,
        spliced,
    }))
}

impl Composer {
    /// Append `src.text[within]` with the includes inside it expanded.
    fn file(
        &mut self,
        src: &Arc<Source>,
        doc: &roxmltree::Document,
        within: Range<usize>,
    ) -> R<()> {
        let mut at = within.start;
        let includes: Vec<Node> = doc
            .descendants()
            .filter(|n| n.has_tag_name("include"))
            .filter(|n| within.contains(&n.range().start))
            .collect();
        for n in includes {
            self.piece(src, at..n.range().start)?;
            self.include(src, n)?;
            at = n.range().end;
        }
        self.piece(src, at..within.end)
    }

    fn piece(&mut self, src: &Arc<Source>, r: Range<usize>) -> R<()> {
        if r.is_empty() {
            return Ok(());
        }
        self.total += r.len();
        if self.total as u64 > crate::input::ROBOT_LIMIT {
            return Err(src.error(
                r.start..r.start,
                "include",
                format!(
                    "the model with its included files is larger than {} MiB, the limit for a robot file",
                    crate::input::ROBOT_LIMIT >> 20
                ),
            ));
        }
        self.pieces.push((src.clone(), r));
        Ok(())
    }

    /// Read the file an `<include>` names and append its root's children.
    fn include(&mut self, src: &Arc<Source>, n: Node) -> R<()> {
        let at = |msg: String| src.error(n.range(), "include", msg);
        if n.children().any(|c| c.is_element()) {
            return Err(at(
                "an <include> holds no elements: it only names a file".into()
            ));
        }
        let Some(file) = n.attribute("file").filter(|f| !f.trim().is_empty()) else {
            return Err(at(
                "<include> needs `file` (a path relative to the main file's folder)".into(),
            ));
        };
        if file.starts_with("package://") {
            return Err(at(format!(
                "`{file}`: MuJoCo reads an include's file relative to the main file's folder; package:// is not understood there"
            )));
        }
        let path = crate::input::resolve(file, &self.dir).map_err(at)?;
        if let Some(k) = self.seen.iter().position(|p| *p == path) {
            let what = if k == 0 {
                "the main file"
            } else {
                "already included"
            };
            return Err(at(format!(
                "`{file}` is {what}: MuJoCo includes a file at most once (an include cycle includes a file again)"
            )));
        }
        if self.seen.len() > MAX_INCLUDES {
            return Err(at(format!("more than {MAX_INCLUDES} included files")));
        }
        self.seen.push(path.clone());
        let bytes = crate::input::read(&path, crate::input::ROBOT_LIMIT)
            .map_err(|e| at(format!("cannot read `{}`: {e}", path.display())))?;
        let text = crate::input::text(bytes).map_err(|e| SceneError {
            file: path.clone(),
            line: e.line,
            column: e.column,
            field: "xml".into(),
            message: format!("the included file {}", e.message),
            excerpt: String::new(),
        })?;
        let child = Arc::new(Source::new(path, text));
        let doc = super::parse_xml(&child)?;
        let root = doc.root_element();
        if !root.has_tag_name("mujoco") {
            return Err(child.error(
                root.range(),
                "include",
                "the root element of an included file must be <mujoco> (MuJoCo inserts its children)",
            ));
        }
        let inner = match (root.first_child(), root.last_child()) {
            (Some(a), Some(b)) => a.range().start..b.range().end,
            _ => return Ok(()), // <mujoco/>: nothing to insert
        };
        self.file(&child, &doc, inner)
    }
}

#[cfg(test)]
mod tests {
    use super::super::mjcf;
    use crate::located::Source;
    use std::path::{Path, PathBuf};

    /// A fresh folder with `files` (name, text) written in it.
    fn folder(tag: &str, files: &[(&str, &str)]) -> PathBuf {
        let d = std::env::temp_dir().join(format!("progmo-include-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        for (name, text) in files {
            let p = d.join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        }
        d
    }

    fn import(path: &Path) -> Result<super::super::urdf::Robot, crate::located::SceneError> {
        let text = std::fs::read_to_string(path).unwrap();
        mjcf::import(&Source::new(path.to_path_buf(), text), &[])
    }

    const WHOLE: &str = r#"<mujoco model="arm">
  <default><joint damping="0.1" armature="0.01"/></default>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" range="-1 1"/>
      <inertial pos="0 0 -0.25" mass="1" diaginertia="0.02 0.02 0.001"/>
      <body name="lower" pos="0 0 -0.5">
        <joint name="elbow" axis="0 1 0" frictionloss="0.2"/>
        <inertial pos="0 0 -0.25" mass="0.5" diaginertia="0.01 0.01 0.001"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"#;

    // the same model in three files: the defaults at the top, the lower arm inside a body, and an
    // include inside an included file whose path is relative to the main file's folder
    const MAIN: &str = r#"<mujoco model="arm">
  <include file="parts/defaults.xml"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" range="-1 1"/>
      <inertial pos="0 0 -0.25" mass="1" diaginertia="0.02 0.02 0.001"/>
      <include file="parts/lower.xml"/>
    </body>
  </worldbody>
</mujoco>
"#;
    const DEFAULTS: &str =
        "<mujoco>\n  <default><joint damping=\"0.1\" armature=\"0.01\"/></default>\n</mujoco>\n";
    const LOWER: &str = r#"<?xml version="1.0"?>
<mujoco model="lower part">
  <body name="lower" pos="0 0 -0.5">
    <joint name="elbow" axis="0 1 0" frictionloss="0.2"/>
    <include file="parts/lower_inertial.xml"/>
  </body>
</mujoco>
"#;
    const LOWER_INERTIAL: &str =
        "<mujoco><inertial pos=\"0 0 -0.25\" mass=\"0.5\" diaginertia=\"0.01 0.01 0.001\"/></mujoco>";

    #[test]
    fn an_included_model_imports_as_the_same_model_written_in_one_file() {
        let d = folder(
            "same",
            &[
                ("whole.xml", WHOLE),
                ("main.xml", MAIN),
                ("parts/defaults.xml", DEFAULTS),
                ("parts/lower.xml", LOWER),
                ("parts/lower_inertial.xml", LOWER_INERTIAL),
            ],
        );
        let (a, b) = (
            import(&d.join("whole.xml")).unwrap(),
            import(&d.join("main.xml")).unwrap(),
        );
        assert_eq!(a.bodies, b.bodies);
        assert_eq!((&a.joints, &a.ranges), (&b.joints, &b.ranges));
        // an unmodelled element of an included file is recorded in that file, at its line
        let f = b
            .unmodelled
            .iter()
            .find(|u| u.kind == "frictionloss")
            .unwrap();
        assert!(f.file.ends_with("parts/lower.xml") && f.line == 4, "{f:?}");
        let r = b
            .unmodelled
            .iter()
            .find(|u| u.kind == "joint_limit")
            .unwrap();
        assert!(r.file.ends_with("main.xml") && r.line == 5, "{r:?}");
        // negative control: a different mass in the included part is a different model
        std::fs::write(
            d.join("parts/lower_inertial.xml"),
            LOWER_INERTIAL.replace("0.5", "0.6"),
        )
        .unwrap();
        assert_ne!(a.bodies, import(&d.join("main.xml")).unwrap().bodies);
    }

    #[test]
    fn an_error_in_an_included_file_is_located_there() {
        let bad = LOWER_INERTIAL.replace("mass=\"0.5\"", "mass=\"heavy\"");
        let d = folder(
            "located",
            &[
                ("main.xml", MAIN),
                ("parts/defaults.xml", DEFAULTS),
                ("parts/lower.xml", LOWER),
                ("parts/lower_inertial.xml", &bad),
            ],
        );
        let e = import(&d.join("main.xml")).unwrap_err();
        assert!(e.file.ends_with("parts/lower_inertial.xml"), "{e}");
        assert_eq!((e.line, e.column), (1, 9), "{e}");
        assert!(e.excerpt.contains("mass=\"heavy\""), "{e}");
    }

    #[test]
    fn refused_includes_are_located_at_the_include() {
        let main = |inc: &str| MAIN.replace("parts/lower.xml", inc);
        let cases = [
            ("missing.xml", "not found"),
            ("main.xml", "is the main file"),
            ("parts/cycle.xml", "already included"),
            ("../outside.xml", "outside the folder"),
            ("package://arm/lower.xml", "package:// is not understood"),
            ("parts/robot.xml", "must be <mujoco>"),
        ];
        for (k, (inc, phrase)) in cases.into_iter().enumerate() {
            let d = folder(
                &format!("refused{k}"),
                &[
                    ("main.xml", &main(inc)),
                    ("parts/defaults.xml", DEFAULTS),
                    (
                        "parts/cycle.xml",
                        "<mujoco><include file=\"parts/cycle.xml\"/></mujoco>",
                    ),
                    ("parts/robot.xml", "<robot name=\"r\"/>"),
                ],
            );
            let e = import(&d.join("main.xml")).unwrap_err();
            assert!(e.message.contains(phrase), "{inc}: {e}");
            let (file, line) = match inc {
                "parts/cycle.xml" => ("parts/cycle.xml", 1),
                "parts/robot.xml" => ("parts/robot.xml", 1),
                _ => ("main.xml", 7),
            };
            assert!(e.file.ends_with(file) && e.line == line, "{inc}: {e}");
        }
        let no_file = MAIN.replace("file=\"parts/lower.xml\"", "");
        let d = folder(
            "nofile",
            &[("main.xml", &no_file), ("parts/defaults.xml", DEFAULTS)],
        );
        let e = import(&d.join("main.xml")).unwrap_err();
        assert!(e.message.contains("needs `file`") && e.line == 7, "{e}");
    }
}
