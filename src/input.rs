//! Input files: the one door through which the core reads a file it is given (a scene, the robot
//! file a scene names). The rules (src/scene/FORMAT.md, "Files"):
//!
//! - where ([`resolve`]): a file a scene names must resolve, symlinks and `..` followed, inside the
//!   scene's folder, a folder of the robot path ([`ROBOT_PATH_VAR`], then
//!   `$ROS_PACKAGE_PATH`; `package://PKG/...` inside its package `DIR/PKG`) or a folder of
//!   [`ALLOW_ROOTS_VAR`]; anything else is refused naming this rule;
//! - what ([`read`]): only regular files; a directory, FIFO, device or socket is refused by name
//!   before it is opened (so a FIFO never blocks and `/dev/zero` is never read), and at most
//!   `limit` bytes are read ([`SCENE_LIMIT`], [`ROBOT_LIMIT`]);
//! - text ([`text`]): UTF-8 without control characters other than tab, CR and LF (TOML and XML
//!   allow no others); a file that is not text is refused by line and column, never quoted, and an
//!   error quotes a line of a file only under [`quotable`].

use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Environment variable: search path (`:`-separated directories) for `package://PKG/rest`: the
/// first `DIR/PKG/rest` that exists. The Python package fills it (when unset) with the
/// `share` directory of an installed `example-robot-data`.
pub const ROBOT_PATH_VAR: &str = "PROGMO_ROBOT_PATH";

/// Environment variable: extra folders (`:`-separated) a scene may read files from, besides its
/// own folder and the robot path.
pub const ALLOW_ROOTS_VAR: &str = "PROGMO_ALLOW_ROOTS";

/// Largest scene file read (bytes): the largest bundled scene is about 5 KiB.
pub const SCENE_LIMIT: u64 = 4 << 20;

/// Largest robot file (URDF, MJCF) read (bytes): example-robot-data's largest is under 1 MiB.
pub const ROBOT_LIMIT: u64 = 64 << 20;

/// Most bodies of a model: a tree scene's `[[model.bodies]]`, a URDF's links, an MJCF's
/// `<body>`s, `[[model.frames]]` included. Real robots have tens to a few hundred.
pub const MAX_BODIES: usize = 4096;

/// Most coordinates: a lagrangian model's `coordinates`, a tree's velocity coordinates. The mass
/// matrix and the formulations' factors are dense n x n (32 MiB each at this limit).
pub const MAX_COORDINATES: usize = 2048;

/// Deepest nesting of XML elements in a robot file (an MJCF chain of bodies nests as deep as it
/// is long; real files nest a few tens).
pub const MAX_XML_DEPTH: usize = 1024;

/// Most XML elements of a robot file (real files: a few thousand), counted before parsing: the
/// parser keeps about 80 bytes per node, and a 64 MiB file of `<a/>` holds 16 million.
pub const MAX_XML_ELEMENTS: usize = 200_000;

/// Most XML attributes of a robot file, counted before parsing (about 40 bytes each in the parser).
pub const MAX_XML_ATTRIBUTES: usize = 1_000_000;

/// Where an XML text first passes [`MAX_XML_ELEMENTS`], [`MAX_XML_ATTRIBUTES`] or
/// [`MAX_XML_DEPTH`]: (byte offset, message). A scan of the tags (comments, CDATA, processing
/// instructions and quoted values skipped), run before the parser allocates anything; a malformed
/// file that passes is left to the parser's own error.
pub fn xml_limits(text: &str) -> Result<(), (usize, String)> {
    let b = text.as_bytes();
    let find = |from: usize, pat: &[u8]| {
        b[from..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map_or(b.len(), |k| from + k + pat.len())
    };
    let (mut i, mut depth, mut elements, mut attributes) = (0, 0usize, 0usize, 0usize);
    // `i` passes the end after an unterminated start tag (`j + 1` below): `get` ends the scan there
    while let Some(k) = b.get(i..).and_then(|r| r.iter().position(|&c| c == b'<')) {
        let at = i + k;
        let rest = &b[at..];
        i = if rest.starts_with(b"<!--") {
            find(at + 4, b"-->")
        } else if rest.starts_with(b"<![CDATA[") {
            find(at + 9, b"]]>")
        } else if rest.starts_with(b"<?") {
            find(at + 2, b"?>")
        } else if rest.starts_with(b"<!") {
            at + 2 // a DTD: the parser refuses it
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            at + 2
        } else {
            // a start tag, up to the first `>` outside quotes
            let (mut j, mut quote) = (at + 1, None);
            while j < b.len() {
                match (quote, b[j]) {
                    (None, q @ (b'"' | b'\'')) => quote = Some(q),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'=') => attributes += 1,
                    (None, b'>') => break,
                    _ => {}
                }
                j += 1;
            }
            elements += 1;
            if elements > MAX_XML_ELEMENTS {
                return Err((
                    at,
                    format!(
                        "more than {MAX_XML_ELEMENTS} XML elements (the limit for a robot file)"
                    ),
                ));
            }
            if attributes > MAX_XML_ATTRIBUTES {
                return Err((at, format!("more than {MAX_XML_ATTRIBUTES} XML attributes (the limit for a robot file)")));
            }
            if b[j.saturating_sub(1)] != b'/' {
                depth += 1;
                if depth > MAX_XML_DEPTH {
                    return Err((at, format!("XML elements nested more than {MAX_XML_DEPTH} deep (the limit for a robot file)")));
                }
            }
            j + 1
        };
    }
    Ok(())
}

/// Longest line an error quotes (characters); a longer line is shown as a window around the column.
pub const QUOTE_WIDTH: usize = 120;

/// Folders of a `:`-separated environment variable (empty entries skipped).
fn var_dirs(var: &str) -> Vec<PathBuf> {
    std::env::var_os(var)
        .map(|v| {
            std::env::split_paths(&v)
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        })
        .unwrap_or_default()
}

/// The robot path: `$PROGMO_ROBOT_PATH`, then `$ROS_PACKAGE_PATH`.
pub fn robot_path() -> Vec<PathBuf> {
    let mut dirs = var_dirs(ROBOT_PATH_VAR);
    dirs.extend(var_dirs("ROS_PACKAGE_PATH"));
    dirs
}

/// The folders of [`ALLOW_ROOTS_VAR`].
pub fn allowed_roots() -> Vec<PathBuf> {
    var_dirs(ALLOW_ROOTS_VAR)
}

/// `..` and `.` removed without touching the file system (an absolute path stays absolute).
pub fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            c => out.push(c),
        }
    }
    out
}

/// The folder a path is inside of, canonical when it exists (symlinks followed).
fn canonical_dir(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| normalize(&absolute(p)))
}

fn absolute(p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(p)
    }
}

fn inside(p: &Path, roots: &[PathBuf]) -> bool {
    roots.iter().any(|r| p.starts_with(r))
}

fn shown(roots: &[PathBuf]) -> String {
    if roots.is_empty() {
        "unset".to_string()
    } else {
        roots
            .iter()
            .map(|r| r.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The file `file` (as a scene's `[model] file` names it) names, checked against the path rule:
/// `package://PKG/rest` is looked up in the robot path and must stay inside `DIR/PKG` (or a folder
/// of [`ALLOW_ROOTS_VAR`]); any other path is relative to `scene_dir` and must stay inside it, a
/// folder of the robot path or of [`ALLOW_ROOTS_VAR`]. Returns the canonical path (symlinks
/// followed); the error says which rule refused it.
pub fn resolve(file: &str, scene_dir: &Path) -> Result<PathBuf, String> {
    let allowed: Vec<PathBuf> = allowed_roots().iter().map(|r| canonical_dir(r)).collect();
    let rule = format!(
        "a file named in a scene (or a sweep file) must resolve inside that file's folder, a folder \
         of the robot path (package://) or of ${ALLOW_ROOTS_VAR} ({}); add its folder to \
         ${ALLOW_ROOTS_VAR} to allow it",
        shown(&allowed)
    );
    if let Some(rest) = file.strip_prefix("package://") {
        let (pkg, tail) = rest.split_once('/').unwrap_or((rest, ""));
        if pkg.is_empty() || pkg == "." || pkg == ".." || tail.is_empty() {
            return Err(format!(
                "`{file}`: a package path is package://PKG/PATH with PKG a package's name (not `.` \
                 or `..`) and PATH inside that package"
            ));
        }
        // `..` may not climb out of the package, whether or not the target exists
        let depth = Path::new(tail).components().try_fold(0i64, |d, c| match c {
            Component::ParentDir if d == 0 => None,
            Component::ParentDir => Some(d - 1),
            Component::Normal(_) => Some(d + 1),
            Component::CurDir => Some(d),
            _ => None,
        });
        if depth.is_none() {
            return Err(format!(
                "`{file}` leaves the folder of package `{pkg}`: a package path stays inside its package"
            ));
        }
        let roots = robot_path();
        let Some((root, found)) = roots
            .iter()
            .map(|r| (r, r.join(pkg).join(tail)))
            .find(|(_, p)| std::fs::metadata(p).is_ok())
        else {
            return Err(format!(
                "`{file}` not found: package `{pkg}` is looked up in ${} and \
                 $ROS_PACKAGE_PATH ({}); for example-robot-data, `pip install example-robot-data` \
                 (the Python `progmo` then finds it) or set {} to its `share` directory",
                ROBOT_PATH_VAR,
                if roots.is_empty() {
                    "both unset".to_string()
                } else {
                    format!("searched {}", roots.len())
                },
                ROBOT_PATH_VAR,
            ));
        };
        let canon = std::fs::canonicalize(&found)
            .map_err(|e| format!("cannot read `{}`: {e}", found.display()))?;
        let pkg_root = canonical_dir(&root.join(pkg));
        if !canon.starts_with(&pkg_root) && !inside(&canon, &allowed) {
            return Err(format!(
                "`{file}` resolves to `{}`, outside the folder of package `{pkg}` ({}): {rule}",
                canon.display(),
                pkg_root.display()
            ));
        }
        return Ok(canon);
    }
    let dir = canonical_dir(scene_dir);
    let mut roots = vec![dir.clone()];
    roots.extend(robot_path().iter().map(|r| canonical_dir(r)));
    roots.extend(allowed.iter().cloned());
    let joined = normalize(&dir.join(file));
    match std::fs::canonicalize(&joined) {
        Ok(canon) if inside(&canon, &roots) => Ok(canon),
        Ok(canon) => Err(format!(
            "`{file}` resolves to `{}`, outside the folder {}: {rule}",
            canon.display(),
            dir.display()
        )),
        // a path outside is refused whether or not it exists (no probing of other folders)
        Err(_) if !inside(&joined, &roots) => Err(format!(
            "`{file}` is outside the folder {}: {rule}",
            dir.display()
        )),
        Err(_) => Err(format!(
            "`{}` not found (relative to the scene file)",
            joined.display()
        )),
    }
}

/// What a file type is when it is not a regular file.
pub(crate) fn not_regular(t: &std::fs::FileType) -> Option<&'static str> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    if t.is_dir() {
        Some("a directory")
    } else if !t.is_file() {
        Some("not a regular file")
    } else {
        None
    }
}

fn mib(n: u64) -> String {
    if n >= 1 << 20 {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

/// The bytes of a regular file of at most `limit` bytes. A directory, FIFO, device or socket is
/// refused by what it is before it is opened (and again on the open handle, should the path have
/// changed in between); the file is opened non-blocking and read through `take(limit + 1)`, so
/// nothing blocks and no more than `limit + 1` bytes are ever held. The error is the reason, to
/// follow "cannot read FILE: ".
pub fn read(path: &Path, limit: u64) -> Result<Vec<u8>, String> {
    let cannot = |e: std::io::Error| e.to_string();
    let refuse =
        |what: &str| format!("it is {what}, not a regular file (only regular files are read)");
    let too_large = || {
        format!(
            "it is larger than {}, the limit for this kind of file",
            mib(limit)
        )
    };
    let meta = std::fs::metadata(path).map_err(cannot)?;
    if let Some(what) = not_regular(&meta.file_type()) {
        return Err(refuse(what));
    }
    if meta.len() > limit {
        return Err(too_large());
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let f = options.open(path).map_err(cannot)?;
    let meta = f.metadata().map_err(cannot)?;
    if let Some(what) = not_regular(&meta.file_type()) {
        return Err(refuse(what));
    }
    let mut bytes = vec![];
    f.take(limit + 1).read_to_end(&mut bytes).map_err(cannot)?;
    if bytes.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(bytes)
}

/// Why bytes are not text, at a 1-based line and column (characters); says nothing of the bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct NotText {
    pub line: usize,
    pub column: usize,
    pub message: String,
}

/// Line and column of byte `at` of valid UTF-8 `s`.
fn position(s: &str, at: usize) -> (usize, usize) {
    let before = &s[..at];
    let start = before.rfind('\n').map_or(0, |i| i + 1);
    (
        before.matches('\n').count() + 1,
        before[start..].chars().count() + 1,
    )
}

/// A control character TOML and XML text may not hold (all of C0 but tab, LF and CR).
fn forbidden(c: char) -> bool {
    c < ' ' && !matches!(c, '\t' | '\n' | '\r')
}

/// Bytes as text: valid UTF-8 without forbidden control characters (a NUL, an escape...).
pub fn text(bytes: Vec<u8>) -> Result<String, NotText> {
    if bytes.starts_with(&[0xff, 0xfe]) || bytes.starts_with(&[0xfe, 0xff]) {
        return Err(NotText {
            line: 1,
            column: 1,
            message: "is UTF-16 (it begins with a byte-order mark): save it as UTF-8".into(),
        });
    }
    let s = match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => {
            let at = e.utf8_error().valid_up_to();
            let valid = std::str::from_utf8(&e.as_bytes()[..at]).unwrap_or("");
            let (line, column) = position(valid, at);
            return Err(NotText {
                line,
                column,
                message: format!(
                    "is not valid UTF-8 (an invalid byte at line {line}, column {column}): save it as UTF-8"
                ),
            });
        }
    };
    if let Some((at, _)) = s.char_indices().find(|(_, c)| forbidden(*c)) {
        let (line, column) = position(&s, at);
        return Err(NotText {
            line,
            column,
            message: format!(
                "is not text: a control character at line {line}, column {column} (TOML and XML \
                 allow only tab, CR and LF)"
            ),
        });
    }
    Ok(s)
}

/// Whether an error may quote a line of `text`: the text holds no forbidden control character
/// (text read through [`text`] never does; text given directly may). With [`excerpt_line`] an
/// error quotes at most one line, of at most [`QUOTE_WIDTH`] characters.
pub fn quotable(text: &str) -> bool {
    !text.chars().any(forbidden)
}

/// The part of `line` an error shows around 1-based `column` (at most [`QUOTE_WIDTH`]
/// characters, `…` where it is cut) and the column of the caret in it.
pub fn excerpt_line(line: &str, column: usize) -> (String, usize) {
    let n = line.chars().count();
    if n <= QUOTE_WIDTH {
        return (line.to_string(), column);
    }
    let c = column.saturating_sub(1).min(n);
    let start = c.saturating_sub(QUOTE_WIDTH / 2).min(n - QUOTE_WIDTH);
    let mut s: String = line.chars().skip(start).take(QUOTE_WIDTH).collect();
    let mut col = c - start + 1;
    if start > 0 {
        s.insert(0, '…');
        col += 1;
    }
    if start + QUOTE_WIDTH < n {
        s.push('…');
    }
    (s, col)
}

/// Whether the first line of `text` that is not blank or a comment can begin a TOML document (a
/// `[table]` header or a `key = value`): a file that does not is not a scene, and no line of it is
/// quoted. Returns that line's number when it cannot.
pub fn toml_start(text: &str) -> Option<usize> {
    let (k, l) = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k, l.trim_start_matches('\u{feff}').trim()))
        .find(|(_, l)| !l.is_empty() && !l.starts_with('#'))?;
    (!(l.starts_with('[') || l.contains('='))).then_some(k + 1)
}

/// Where `text` fails to begin as an XML document (its first character other than a byte-order
/// mark or white space is not `<`): 1-based line and column, None when it begins as one.
pub fn xml_start(text: &str) -> Option<(usize, usize)> {
    let at = text.find(|c: char| !(c.is_whitespace() || c == '\u{feff}'))?;
    (!text[at..].starts_with('<')).then(|| position(text, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unterminated_tag_ends_the_xml_scan() {
        // found by tests/fuzz_props.rs on a mutated MJCF file: the scan indexed past the end
        for t in ["<robot name='a'", "<a><b c=\"1\"", "<a", "<"] {
            assert_eq!(xml_limits(t), Ok(()), "{t}");
        }
        let deep = "<a>".repeat(MAX_XML_DEPTH + 1);
        assert!(xml_limits(&deep).unwrap_err().1.contains("nested"));
    }

    #[test]
    fn normalize_removes_dots_lexically() {
        assert_eq!(normalize(Path::new("/a/b/../c/./d")), Path::new("/a/c/d"));
        assert_eq!(normalize(Path::new("/a/../../etc")), Path::new("/etc"));
    }

    #[test]
    fn text_refuses_nul_and_bad_utf8_by_position_only() {
        let e = text(b"A=1\nB=se\0cret".to_vec()).unwrap_err();
        assert_eq!((e.line, e.column), (2, 5));
        assert!(!e.message.contains("se") || e.message.contains("save"));
        assert!(!e.message.contains("cret"), "{}", e.message);
        let e = text(b"ab\ncd\xffsecret".to_vec()).unwrap_err();
        assert_eq!((e.line, e.column), (2, 3));
        assert!(!e.message.contains("secret"));
        assert_eq!(text(b"a\tb\r\nc".to_vec()).unwrap(), "a\tb\r\nc");
    }

    #[test]
    fn excerpts_are_cut_to_the_quote_width_around_the_column() {
        let line: String = (0..1000)
            .map(|i| char::from(b'a' + (i % 26) as u8))
            .collect();
        let (s, col) = excerpt_line(&line, 500);
        assert!(s.chars().count() <= QUOTE_WIDTH + 2);
        assert_eq!(s.chars().nth(col - 1), line.chars().nth(499));
        assert_eq!(excerpt_line("short", 3), ("short".to_string(), 3));
        let (s, col) = excerpt_line(&line, 1);
        assert_eq!((s.chars().count(), col), (QUOTE_WIDTH + 1, 1));
    }

    #[test]
    fn format_starts() {
        assert_eq!(toml_start("# c\n\nname = \"x\"\n"), None);
        assert_eq!(toml_start("[model]\n"), None);
        assert_eq!(toml_start("\n# c\nSECRET_TOKEN\n"), Some(3));
        assert_eq!(xml_start("\u{feff}\n <robot/>"), None);
        assert_eq!(xml_start("\nSECRET"), Some((2, 1)));
    }

    #[cfg(unix)]
    #[test]
    fn only_regular_files_are_read_within_the_limit() {
        let e = read(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(e.contains("a character device"), "{e}");
        let e = read(Path::new("/"), 1 << 20).unwrap_err();
        assert!(e.contains("a directory"), "{e}");
        let dir = std::env::temp_dir().join(format!("progmo-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: mkfifo on a NUL-terminated path
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = read(&fifo, 1 << 20).unwrap_err();
        assert!(e.contains("a FIFO"), "{e}");
        let big = dir.join("big");
        std::fs::write(&big, vec![b'x'; 2048]).unwrap();
        assert!(read(&big, 1024).unwrap_err().contains("larger than"));
        assert_eq!(read(&big, 4096).unwrap().len(), 2048);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
