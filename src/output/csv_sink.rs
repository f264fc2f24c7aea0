//! Streaming CSV writer and reader (format: see the module docs of [`crate::output`]).

use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, Read, Write};
use std::path::Path;

use super::{OutputError, OutputSink, SampleLayout};
use crate::solve::{Sample, SampleSink, Trajectory};

/// Streams samples to CSV, one line per sample.
pub struct CsvSink<W: Write> {
    writer: csv::Writer<W>,
    layout: SampleLayout,
    file: String,
    field: String,
    error: Option<OutputError>,
}

fn csv_to_io(e: csv::Error) -> io::Error {
    if e.is_io_error() {
        if let csv::ErrorKind::Io(e) = e.into_kind() {
            return e;
        }
        unreachable!()
    }
    io::Error::other(e)
}

impl CsvSink<File> {
    /// Create (truncate) the file at `path` and write the header.
    pub fn create(path: impl AsRef<Path>, layout: &SampleLayout) -> Result<Self, OutputError> {
        let name = path.as_ref().display().to_string();
        let f = File::create(path.as_ref()).map_err(|e| OutputError::io(&name, "create", e))?;
        Self::new(f, layout, &name)
    }
}

impl<W: Write> CsvSink<W> {
    /// Write the header to `w`; `file` names the destination in errors.
    pub fn new(w: W, layout: &SampleLayout, file: &str) -> Result<Self, OutputError> {
        let writer = csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .from_writer(w);
        let mut sink = CsvSink {
            writer,
            layout: layout.clone(),
            file: file.to_string(),
            field: String::with_capacity(32),
            error: None,
        };
        let header = header(layout);
        sink.writer
            .write_record(&header)
            .map_err(|e| OutputError::io(file, "write header", csv_to_io(e)))?;
        Ok(sink)
    }

    /// The column names written.
    pub fn header(&self) -> Vec<String> {
        header(&self.layout)
    }

    /// The first error met so far, if any.
    pub fn error(&self) -> Option<&OutputError> {
        self.error.as_ref()
    }

    /// Finish and return the underlying writer.
    pub fn into_inner(mut self) -> Result<W, OutputError> {
        self.finish()?;
        let file = self.file.clone();
        self.writer
            .into_inner()
            .map_err(|e| OutputError::io(&file, "flush", io::Error::other(e.to_string())))
    }

    fn write_sample(&mut self, s: &Sample<'_>) -> Result<(), OutputError> {
        self.layout
            .check(s)
            .map_err(|m| OutputError::invalid(&self.file, m))?;
        let groups: [&[f64]; 7] = [s.q, s.v, s.a, s.u, s.lambda, s.residual, s.residual_rate];
        let reactions = if self.layout.reactions {
            s.reactions
        } else {
            &[]
        };
        let t = [s.t];
        let all = [
            &t[..],
            groups[0],
            groups[1],
            groups[2],
            groups[3],
            reactions,
        ]
        .into_iter()
        .chain(groups[4..].iter().copied());
        for g in all {
            for &x in g {
                self.field.clear();
                write!(self.field, "{x:e}").expect("formatting into a String");
                self.writer
                    .write_field(self.field.as_bytes())
                    .map_err(|e| OutputError::io(&self.file, "write", csv_to_io(e)))?;
            }
        }
        self.writer
            .write_record(None::<&[u8]>)
            .map_err(|e| OutputError::io(&self.file, "write", csv_to_io(e)))
    }
}

fn header(layout: &SampleLayout) -> Vec<String> {
    let mut h = vec!["t".to_string()];
    let mut group = |prefix: &str, names: &[String]| {
        h.extend(names.iter().map(|n| format!("{prefix}:{n}")));
    };
    group("q", &layout.q_names);
    group("v", &layout.v_names);
    group("a", &layout.v_names);
    group("u", &layout.v_names);
    if layout.reactions {
        group("reaction", &layout.v_names);
    }
    group("lambda", &layout.row_names);
    group("residual", &layout.row_names);
    group("residual_rate", &layout.row_names);
    h
}

impl<W: Write> SampleSink for CsvSink<W> {
    fn sample(&mut self, s: &Sample<'_>) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = self.write_sample(s) {
            self.error = Some(e);
        }
    }
}

impl<W: Write> OutputSink for CsvSink<W> {
    fn finish(&mut self) -> Result<(), OutputError> {
        if self.error.is_none() {
            if let Err(e) = self.writer.flush() {
                self.error = Some(OutputError::io(&self.file, "flush", e));
            }
        }
        match &self.error {
            None => Ok(()),
            Some(e) => Err(e.replay()),
        }
    }
}

/// Read a CSV file written by [`CsvSink`] into a [`Trajectory`]. Without reaction columns the
/// reactions are zero; without `residual_rate` columns the rates are zero.
pub fn read_csv(path: impl AsRef<Path>) -> Result<Trajectory, OutputError> {
    let name = path.as_ref().display().to_string();
    let f = File::open(path.as_ref()).map_err(|e| OutputError::io(&name, "open", e))?;
    read_csv_from(f, &name)
}

#[derive(Clone, Copy, PartialEq, PartialOrd, Debug)]
enum Group {
    T,
    Q,
    V,
    A,
    U,
    Reaction,
    Lambda,
    Residual,
    ResidualRate,
}

impl Group {
    fn of(prefix: &str) -> Option<Group> {
        Some(match prefix {
            "q" => Group::Q,
            "v" => Group::V,
            "a" => Group::A,
            "u" => Group::U,
            "reaction" => Group::Reaction,
            "lambda" => Group::Lambda,
            "residual" => Group::Residual,
            "residual_rate" => Group::ResidualRate,
            _ => return None,
        })
    }
}

/// Read CSV from `r`; `file` names the source in errors.
#[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
pub fn read_csv_from<R: Read>(r: R, file: &str) -> Result<Trajectory, OutputError> {
    let mut reader = csv::ReaderBuilder::new().has_headers(true).from_reader(r);
    let parse_err =
        |line: u64, column: usize, header: Option<String>, message: String| OutputError::Parse {
            file: file.to_string(),
            line,
            column,
            header,
            message,
        };
    let csv_err = |e: csv::Error| {
        let line = e.position().map(|p| p.line()).unwrap_or(0);
        if e.is_io_error() {
            OutputError::io(file, "read", csv_to_io(e))
        } else {
            parse_err(line, 0, None, e.to_string())
        }
    };
    let headers = reader.headers().map_err(csv_err)?.clone();
    // Column index -> group; names per group.
    let mut groups = Vec::with_capacity(headers.len());
    let mut names: [Vec<String>; 9] = Default::default();
    let mut last = Group::T;
    for (j, h) in headers.iter().enumerate() {
        let g = if j == 0 {
            if h != "t" {
                return Err(parse_err(
                    1,
                    1,
                    Some(h.to_string()),
                    "the first column must be `t`".into(),
                ));
            }
            Group::T
        } else {
            let (prefix, name) = h.split_once(':').ok_or_else(|| {
                parse_err(
                    1,
                    j + 1,
                    Some(h.to_string()),
                    "expected `<group>:<name>`".into(),
                )
            })?;
            let g = Group::of(prefix).ok_or_else(|| {
                parse_err(
                    1,
                    j + 1,
                    Some(h.to_string()),
                    format!("unknown group `{prefix}`"),
                )
            })?;
            if g < last {
                return Err(parse_err(
                    1,
                    j + 1,
                    Some(h.to_string()),
                    format!("group `{prefix}` out of order (after {last:?})"),
                ));
            }
            names[g as usize].push(name.to_string());
            g
        };
        last = g;
        groups.push(g);
    }
    if headers.is_empty() {
        return Err(parse_err(1, 0, None, "empty header".into()));
    }
    let [_, q_names, v_names, a_names, u_names, r_names, l_names, res_names, rate_names] = names;
    let has_reactions = !r_names.is_empty() || v_names.is_empty();
    for (g, n) in [("a", &a_names), ("u", &u_names), ("reaction", &r_names)] {
        if n != &v_names && !(g == "reaction" && n.is_empty()) {
            return Err(parse_err(
                1,
                0,
                None,
                format!("the `{g}:` columns do not name the same coordinates as the `v:` columns"),
            ));
        }
    }
    if res_names != l_names || (rate_names != l_names && !rate_names.is_empty()) {
        return Err(parse_err(
            1,
            0,
            None,
            "the `lambda:`, `residual:` and `residual_rate:` columns do not name the same rows"
                .into(),
        ));
    }
    let has_rates = !rate_names.is_empty() || l_names.is_empty();
    let nv = v_names.len();
    let ns = l_names.len();
    let mut traj = Trajectory {
        q_names,
        v_names,
        row_names: l_names,
        ..Default::default()
    };
    let mut record = csv::StringRecord::new();
    while reader.read_record(&mut record).map_err(csv_err)? {
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        for (j, (field, &g)) in record.iter().zip(&groups).enumerate() {
            let x: f64 = field.trim().parse().map_err(|e| {
                parse_err(
                    line,
                    j + 1,
                    Some(headers[j].to_string()),
                    format!("`{field}` is not a number ({e})"),
                )
            })?;
            let dst = match g {
                Group::T => &mut traj.t,
                Group::Q => &mut traj.q,
                Group::V => &mut traj.v,
                Group::A => &mut traj.a,
                Group::U => &mut traj.u,
                Group::Reaction => &mut traj.reactions,
                Group::Lambda => &mut traj.lambda,
                Group::Residual => &mut traj.residual,
                Group::ResidualRate => &mut traj.residual_rate,
            };
            dst.push(x);
        }
        if !has_reactions {
            traj.reactions.extend(std::iter::repeat_n(0.0, nv));
        }
        if !has_rates {
            traj.residual_rate.extend(std::iter::repeat_n(0.0, ns));
        }
    }
    Ok(traj)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::testutil::{feed, layout, sample_values};

    fn write(layout: &SampleLayout, n: usize) -> Vec<u8> {
        let mut sink = CsvSink::new(Vec::new(), layout, "<memory>").unwrap();
        feed(&mut sink, layout, n, 0.1);
        sink.into_inner().unwrap()
    }

    #[test]
    fn header_names_every_column_in_order() {
        let l = layout();
        let bytes = write(&l, 0);
        let text = String::from_utf8(bytes).unwrap();
        assert_eq!(
            text,
            "t,q:x,\"q:th,eta\",v:vx,\"v:w\"\"z\",a:vx,\"a:w\"\"z\",u:vx,\"u:w\"\"z\",\
             reaction:vx,\"reaction:w\"\"z\",lambda:speed,lambda:pos:1,lambda:sys,\
             residual:speed,residual:pos:1,residual:sys,\
             residual_rate:speed,residual_rate:pos:1,residual_rate:sys\n"
        );
        let no_r = l.clone().with_reactions(false);
        let sink = CsvSink::new(Vec::new(), &no_r, "<memory>").unwrap();
        assert!(!sink.header().iter().any(|h| h.starts_with("reaction:")));
        assert_eq!(sink.header().len(), 1 + 2 + 3 * 2 + 3 * 3);
    }

    #[test]
    fn roundtrip_is_bit_exact() {
        let l = layout();
        let n = 7;
        let bytes = write(&l, n);
        let traj = read_csv_from(&bytes[..], "<memory>").unwrap();
        assert_eq!(traj.q_names, l.q_names);
        assert_eq!(traj.v_names, l.v_names);
        assert_eq!(traj.row_names, l.row_names);
        assert_eq!(traj.len(), n);
        let mut expect = l.trajectory();
        feed(&mut expect, &l, n, 0.1);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (a, b) in [
            (&traj.t, &expect.t),
            (&traj.q, &expect.q),
            (&traj.v, &expect.v),
            (&traj.a, &expect.a),
            (&traj.u, &expect.u),
            (&traj.reactions, &expect.reactions),
            (&traj.lambda, &expect.lambda),
            (&traj.residual, &expect.residual),
            (&traj.residual_rate, &expect.residual_rate),
        ] {
            assert_eq!(bits(a), bits(b));
        }
        // The values really exercise precision: -0, subnormal-range and large magnitudes.
        let vals = sample_values(&l, 3);
        assert!(vals
            .iter()
            .flatten()
            .any(|x| x.to_bits() == (-0.0f64).to_bits()));
    }

    #[test]
    fn without_reactions_reads_zeros() {
        let l = layout().with_reactions(false);
        let bytes = write(&l, 3);
        let traj = read_csv_from(&bytes[..], "<memory>").unwrap();
        assert_eq!(traj.reactions, vec![0.0; 3 * 2]);
        assert_eq!(traj.reactions_at(2).len(), 2);
    }

    #[test]
    fn non_finite_values_roundtrip() {
        let l = SampleLayout {
            q_names: vec!["x".into()],
            ..Default::default()
        };
        let mut sink = CsvSink::new(Vec::new(), &l, "<memory>").unwrap();
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 5e-324] {
            sink.sample(&Sample {
                t: 1.0,
                q: &[x],
                v: &[],
                a: &[],
                u: &[],
                reactions: &[],
                lambda: &[],
                residual: &[],
                residual_rate: &[],
            });
        }
        let bytes = sink.into_inner().unwrap();
        let traj = read_csv_from(&bytes[..], "<memory>").unwrap();
        assert!(traj.q[0].is_nan());
        assert_eq!(&traj.q[1..], &[f64::INFINITY, f64::NEG_INFINITY, 5e-324]);
    }

    #[test]
    fn parse_errors_name_line_and_column() {
        let text = "t,q:x,v:vx,a:vx,u:vx\n0e0,1e0,2e0,3e0,4e0\n1e0,1e0,oops,3e0,4e0\n";
        let err = read_csv_from(text.as_bytes(), "bad.csv").unwrap_err();
        match &err {
            OutputError::Parse {
                line,
                column,
                header,
                ..
            } => {
                assert_eq!((*line, *column), (3, 3));
                assert_eq!(header.as_deref(), Some("v:vx"));
            }
            e => panic!("unexpected {e}"),
        }
        let msg = err.to_string();
        assert!(msg.starts_with("bad.csv: line 3, column 3 (v:vx)"), "{msg}");

        let short = "t,q:x\n0e0,1e0\n1e0\n";
        let err = read_csv_from(short.as_bytes(), "short.csv").unwrap_err();
        assert!(matches!(err, OutputError::Parse { line: 3, .. }), "{err}");

        for bad in [
            "x,q:x\n",
            "t,q:x,w:y\n",
            "t,v:x,q:y\n",
            "t,qx\n",
            "t,v:a,a:b\n",
        ] {
            let err = read_csv_from(bad.as_bytes(), "h.csv").unwrap_err();
            assert!(
                matches!(err, OutputError::Parse { line: 1, .. }),
                "{bad}: {err}"
            );
        }
    }

    struct Failing {
        budget: usize,
    }
    impl Write for Failing {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if buf.len() > self.budget {
                return Err(io::Error::other("disk full"));
            }
            self.budget -= buf.len();
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn io_errors_are_kept_and_returned_by_finish() {
        let l = layout();
        let mut sink = CsvSink::new(Failing { budget: 20_000 }, &l, "full.csv").unwrap();
        // Far more than the budget; must not panic.
        feed(&mut sink, &l, 1000, 0.1);
        let err = sink.finish().unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("full.csv") && msg.contains("disk full"),
            "{msg}"
        );
        assert!(sink.finish().is_err());
    }

    #[test]
    fn wrong_sample_length_is_an_error() {
        let l = layout();
        let mut sink = CsvSink::new(Vec::new(), &l, "<memory>").unwrap();
        sink.sample(&Sample {
            t: 0.0,
            q: &[1.0],
            v: &[],
            a: &[],
            u: &[],
            reactions: &[],
            lambda: &[],
            residual: &[],
            residual_rate: &[],
        });
        assert!(matches!(sink.finish(), Err(OutputError::Invalid { .. })));
    }

    #[test]
    fn file_roundtrip() {
        let l = layout();
        let path = std::env::temp_dir().join(format!("progmo-csv-{}.csv", std::process::id()));
        let mut sink = CsvSink::create(&path, &l).unwrap();
        feed(&mut sink, &l, 4, 0.5);
        sink.finish().unwrap();
        drop(sink);
        let traj = read_csv(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(traj.t, vec![0.0, 0.5, 1.0, 1.5]);
        // Dropping without finish still flushes.
        let mut sink = CsvSink::create(&path, &l).unwrap();
        feed(&mut sink, &l, 3, 0.5);
        drop(sink);
        assert_eq!(read_csv(&path).unwrap().len(), 3);
        std::fs::remove_file(&path).ok();
        let missing = read_csv(path.with_extension("nope")).unwrap_err();
        assert!(matches!(missing, OutputError::Io { .. }));
    }
}
