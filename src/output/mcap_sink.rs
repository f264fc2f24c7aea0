//! MCAP recorder with JSON messages (format: see the module docs of [`crate::output`]).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use mcap::records::MessageHeader;
use serde::Serialize;
use serde_json::json;

use super::{OutputError, OutputSink, SampleLayout};
use crate::solve::{Sample, SampleSink};

/// Topic of the channel added by [`McapSink::add_frame_transform_channel`].
pub const FRAME_TRANSFORM_TOPIC: &str = "/progmo/tf";
/// Topic of a tree scene's geometry (`foxglove.SceneUpdate`, written once).
pub const SCENE_TOPIC: &str = "/progmo/scene";
/// Schema name of frame transforms (recognized by Foxglove's 3D panel).
pub const FRAME_TRANSFORM_SCHEMA: &str = "foxglove.FrameTransform";

/// A channel added with [`McapSink::add_json_channel`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct McapChannel(u16);

/// Records samples into an MCAP file: one JSON message per sample on `/progmo/state`,
/// `/progmo/control`, `/progmo/residual` and (if `SampleLayout::reactions`) `/progmo/reaction`.
pub struct McapSink<W: Write + Seek> {
    writer: Option<mcap::Writer<W>>,
    done: Option<W>,
    file: String,
    layout: SampleLayout,
    state: u16,
    control: u16,
    residual: u16,
    reaction: Option<u16>,
    tf: Option<u16>,
    warning_channel: Option<McapChannel>,
    /// Tree scenes: body frames per sample on /progmo/tf and the geometry on /progmo/scene.
    /// (bodies, the scene channel once written, the child frame id of each body)
    bodies: Option<(super::Bodies, Option<McapChannel>, Vec<String>)>,
    /// Time of the last sample (the traces are written there at `finish`).
    last_t: f64,
    sequence: BTreeMap<u16, u32>,
    q_keys: Vec<String>,
    v_keys: Vec<String>,
    row_keys: Vec<String>,
    buf: String,
    bytes: Vec<u8>,
    error: Option<OutputError>,
}

/// Log time of sample time t: round(t * 1e9) ns; negative or NaN give 0.
pub(crate) fn log_time(t: f64) -> u64 {
    (t * 1e9).round() as u64
}

/// JSON schema of an object mapping `names` to numbers (null for non-finite values).
fn named_numbers(names: &[String]) -> serde_json::Value {
    let props: serde_json::Map<String, serde_json::Value> = names
        .iter()
        .map(|n| (n.clone(), json!({"type": ["number", "null"]})))
        .collect();
    json!({"type": "object", "properties": props, "required": names})
}

fn object_schema(title: &str, fields: &[(&str, serde_json::Value)]) -> serde_json::Value {
    let mut props = serde_json::Map::new();
    props.insert("t".into(), json!({"type": "number", "description": "time"}));
    for (k, v) in fields {
        props.insert(k.to_string(), v.clone());
    }
    let mut required: Vec<&str> = vec!["t"];
    required.extend(fields.iter().map(|(k, _)| *k));
    json!({"title": title, "type": "object", "properties": props, "required": required})
}

/// The JSON schemas of the recordings, by schema name (`progmo.State`, `progmo.Control`,
/// `progmo.Residual`, `progmo.Reaction`, `foxglove.FrameTransform`, `foxglove.SceneUpdate`): shared with `progmo debug` (through the binding) so its
/// recordings have the same layout as `progmo solve`'s.
pub fn recording_schemas(layout: &SampleLayout) -> Vec<(&'static str, serde_json::Value)> {
    let q = named_numbers(&layout.q_names);
    let v = named_numbers(&layout.v_names);
    let rows = named_numbers(&layout.row_names);
    vec![
        (
            "progmo.State",
            object_schema(
                "progmo.State",
                &[("q", q), ("v", v.clone()), ("a", v.clone())],
            ),
        ),
        (
            "progmo.Control",
            object_schema(
                "progmo.Control",
                &[("u", v.clone()), ("lambda", rows.clone())],
            ),
        ),
        (
            "progmo.Residual",
            object_schema(
                "progmo.Residual",
                &[("residual", rows.clone()), ("residual_rate", rows)],
            ),
        ),
        (
            "progmo.Reaction",
            object_schema("progmo.Reaction", &[("reaction", v)]),
        ),
        (FRAME_TRANSFORM_SCHEMA, frame_transform_schema()),
        ("foxglove.SceneUpdate", super::scene_update_schema()),
    ]
}

fn frame_transform_schema() -> serde_json::Value {
    let num = || json!({"type": "number"});
    json!({
        "title": FRAME_TRANSFORM_SCHEMA,
        "description": "Transform from the parent frame to the child frame",
        "type": "object",
        "properties": {
            "timestamp": {
                "type": "object",
                "title": "time",
                "properties": {
                    "sec": {"type": "integer", "minimum": 0},
                    "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999u32}
                }
            },
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": {
                "type": "object",
                "title": "foxglove.Vector3",
                "properties": {"x": num(), "y": num(), "z": num()}
            },
            "rotation": {
                "type": "object",
                "title": "foxglove.Quaternion",
                "properties": {"x": num(), "y": num(), "z": num(), "w": num()}
            }
        }
    })
}

#[derive(Serialize)]
struct Time {
    sec: u64,
    nsec: u32,
}
#[derive(Serialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}
#[derive(Serialize)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}
#[derive(Serialize)]
struct FrameTransform<'a> {
    timestamp: Time,
    parent_frame_id: &'a str,
    child_frame_id: &'a str,
    translation: Vector3,
    rotation: Quaternion,
}

fn keys(names: &[String]) -> Vec<String> {
    names
        .iter()
        .map(|n| serde_json::to_string(n).expect("a string serializes"))
        .collect()
}

/// Append `"field":{key:value,...}` to `buf`.
fn push_object(buf: &mut String, field: &str, keys: &[String], values: &[f64]) {
    let _ = write!(buf, ",\"{field}\":{{");
    for (i, (k, &x)) in keys.iter().zip(values).enumerate() {
        if i > 0 {
            buf.push(',');
        }
        buf.push_str(k);
        buf.push(':');
        push_number(buf, x);
    }
    buf.push('}');
}

fn push_number(buf: &mut String, x: f64) {
    if x.is_finite() {
        let _ = write!(buf, "{x:e}");
    } else {
        buf.push_str("null");
    }
}

impl McapSink<BufWriter<File>> {
    /// Create (truncate) the file at `path` and write the header, schemas and channels.
    pub fn create(path: impl AsRef<Path>, layout: &SampleLayout) -> Result<Self, OutputError> {
        let name = path.as_ref().display().to_string();
        let f = File::create(path.as_ref()).map_err(|e| OutputError::io(&name, "create", e))?;
        Self::new(BufWriter::new(f), layout, &name)
    }
}

impl<W: Write + Seek> McapSink<W> {
    /// Start a recording in `w`; `file` names the destination in errors.
    pub fn new(w: W, layout: &SampleLayout, file: &str) -> Result<Self, OutputError> {
        let options = mcap::WriteOptions::new()
            .compression(None)
            .library(format!("progmo {}", env!("CARGO_PKG_VERSION")));
        let writer = options
            .create(w)
            .map_err(|e| OutputError::mcap(file, "start recording", e))?;
        let mut sink = McapSink {
            writer: Some(writer),
            done: None,
            file: file.to_string(),
            layout: layout.clone(),
            state: 0,
            control: 0,
            residual: 0,
            reaction: None,
            tf: None,
            warning_channel: None,
            bodies: None,
            last_t: 0.0,
            sequence: BTreeMap::new(),
            q_keys: keys(&layout.q_names),
            v_keys: keys(&layout.v_names),
            row_keys: keys(&layout.row_names),
            buf: String::new(),
            bytes: Vec::new(),
            error: None,
        };
        let schemas = recording_schemas(layout);
        let schema = |name: &str| {
            schemas
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, s)| s.clone())
                .unwrap_or_default()
        };
        sink.state = sink
            .add_json_channel("/progmo/state", "progmo.State", &schema("progmo.State"))?
            .0;
        sink.control = sink
            .add_json_channel(
                "/progmo/control",
                "progmo.Control",
                &schema("progmo.Control"),
            )?
            .0;
        sink.residual = sink
            .add_json_channel(
                "/progmo/residual",
                "progmo.Residual",
                &schema("progmo.Residual"),
            )?
            .0;
        if layout.reactions {
            sink.reaction = Some(
                sink.add_json_channel(
                    "/progmo/reaction",
                    "progmo.Reaction",
                    &schema("progmo.Reaction"),
                )?
                .0,
            );
        }
        Ok(sink)
    }

    /// Add a channel with JSON messages described by the JSON schema `schema` named
    /// `schema_name`. Fails after `finish`.
    pub fn add_json_channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema: &serde_json::Value,
    ) -> Result<McapChannel, OutputError> {
        let file = self.file.clone();
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| OutputError::invalid(&file, format!("add {topic} after finish")))?;
        let data = serde_json::to_vec(schema).map_err(|e| OutputError::Json {
            file: file.clone(),
            what: format!("schema of {topic}"),
            source: e,
        })?;
        let schema_id = w
            .add_schema(schema_name, "jsonschema", &data)
            .map_err(|e| OutputError::mcap(&file, format!("add schema {schema_name}"), e))?;
        let id = w
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| OutputError::mcap(&file, format!("add channel {topic}"), e))?;
        Ok(McapChannel(id))
    }

    /// Record the mechanism of a tree scene: at every sample the world pose of each body on
    /// [`FRAME_TRANSFORM_TOPIC`] (child frame `progmo/<body>`), and at the first sample its
    /// geometry on [`SCENE_TOPIC`] (see [`super::Bodies::scene_update`]); at `finish`, the traces
    /// of the programme's sites on [`SCENE_TOPIC`] at the last sample's time.
    pub fn with_bodies(mut self, bodies: super::Bodies) -> Self {
        let frames = bodies.names().map(|n| format!("progmo/{n}")).collect();
        self.bodies = Some((bodies, None, frames));
        self
    }

    fn write_bodies(&mut self, t: f64, q: &[f64]) {
        let Some((mut bodies, scene, frames)) = self.bodies.take() else {
            return;
        };
        let scene = match scene {
            Some(ch) => Some(ch),
            None => {
                let update = bodies.scene_update(q, "progmo", 1.0, true);
                match self.add_json_channel(
                    SCENE_TOPIC,
                    "foxglove.SceneUpdate",
                    &super::scene_update_schema(),
                ) {
                    Ok(ch) => {
                        self.write_json(ch, t, &update);
                        Some(ch)
                    }
                    Err(e) => {
                        self.error = Some(e);
                        None
                    }
                }
            }
        };
        for (p, frame) in bodies.record(q).iter().zip(&frames) {
            self.frame_transform(t, "world", frame, p.position, p.quaternion);
        }
        self.bodies = Some((bodies, scene, frames));
    }

    /// Add the frame-transform channel ([`FRAME_TRANSFORM_TOPIC`], schema
    /// [`FRAME_TRANSFORM_SCHEMA`]) if not added yet.
    pub fn add_frame_transform_channel(&mut self) -> Result<McapChannel, OutputError> {
        if let Some(id) = self.tf {
            return Ok(McapChannel(id));
        }
        let ch = self.add_json_channel(
            FRAME_TRANSFORM_TOPIC,
            FRAME_TRANSFORM_SCHEMA,
            &frame_transform_schema(),
        )?;
        self.tf = Some(ch.0);
        Ok(ch)
    }

    /// Record the pose of frame `child` in frame `parent` at time t (adding the frame-transform
    /// channel if needed). Message: `{"timestamp": {"sec", "nsec"}, "parent_frame_id",
    /// "child_frame_id", "translation": {"x","y","z"}, "rotation": {"x","y","z","w"}}`, the
    /// timestamp being the log time split into seconds and nanoseconds. Errors are kept for
    /// `finish`.
    pub fn frame_transform(
        &mut self,
        t: f64,
        parent: &str,
        child: &str,
        translation: [f64; 3],
        rotation_wxyz: [f64; 4],
    ) {
        if self.error.is_some() || self.writer.is_none() {
            return;
        }
        let ch = match self.add_frame_transform_channel() {
            Ok(ch) => ch,
            Err(e) => {
                self.error = Some(e);
                return;
            }
        };
        let ns = log_time(t);
        let [w, x, y, z] = rotation_wxyz;
        let msg = FrameTransform {
            timestamp: Time {
                sec: ns / 1_000_000_000,
                nsec: (ns % 1_000_000_000) as u32,
            },
            parent_frame_id: parent,
            child_frame_id: child,
            translation: Vector3 {
                x: translation[0],
                y: translation[1],
                z: translation[2],
            },
            rotation: Quaternion { x, y, z, w },
        };
        self.write_json(ch, t, &msg);
    }

    /// Write `msg` as JSON on an added channel at time t. Errors are kept for `finish`.
    pub fn write_json<T: Serialize>(&mut self, channel: McapChannel, t: f64, msg: &T) {
        if self.error.is_some() || self.writer.is_none() {
            return;
        }
        let mut bytes = std::mem::take(&mut self.bytes);
        bytes.clear();
        match serde_json::to_writer(&mut bytes, msg) {
            Ok(()) => self.write_raw(channel.0, t, &bytes),
            Err(e) => {
                self.error = Some(OutputError::Json {
                    file: self.file.clone(),
                    what: "serialize message".into(),
                    source: e,
                })
            }
        }
        self.bytes = bytes;
    }

    fn write_raw(&mut self, channel: u16, t: f64, data: &[u8]) {
        if self.error.is_some() {
            return;
        }
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        let seq = self.sequence.entry(channel).or_insert(0);
        let ns = log_time(t);
        let header = MessageHeader {
            channel_id: channel,
            sequence: *seq,
            log_time: ns,
            publish_time: ns,
        };
        *seq = seq.wrapping_add(1);
        if let Err(e) = w.write_to_known_channel(&header, data) {
            self.error = Some(OutputError::mcap(&self.file, "write message", e));
        }
    }

    /// The first error met so far, if any.
    pub fn error(&self) -> Option<&OutputError> {
        self.error.as_ref()
    }

    /// Finish and return the underlying writer.
    pub fn into_inner(mut self) -> Result<W, OutputError> {
        self.finish()?;
        Ok(self.done.take().expect("finish keeps the writer"))
    }

    fn write_sample(&mut self, s: &Sample<'_>) {
        if let Err(m) = self.layout.check(s) {
            self.error = Some(OutputError::invalid(&self.file, m));
            return;
        }
        let mut buf = std::mem::take(&mut self.buf);
        let start = |buf: &mut String| {
            buf.clear();
            buf.push_str("{\"t\":");
            push_number(buf, s.t);
        };
        start(&mut buf);
        push_object(&mut buf, "q", &self.q_keys, s.q);
        push_object(&mut buf, "v", &self.v_keys, s.v);
        push_object(&mut buf, "a", &self.v_keys, s.a);
        buf.push('}');
        self.write_raw(self.state, s.t, buf.as_bytes());

        start(&mut buf);
        push_object(&mut buf, "u", &self.v_keys, s.u);
        push_object(&mut buf, "lambda", &self.row_keys, s.lambda);
        buf.push('}');
        self.write_raw(self.control, s.t, buf.as_bytes());

        start(&mut buf);
        push_object(&mut buf, "residual", &self.row_keys, s.residual);
        push_object(&mut buf, "residual_rate", &self.row_keys, s.residual_rate);
        buf.push('}');
        self.write_raw(self.residual, s.t, buf.as_bytes());

        if let Some(ch) = self.reaction {
            start(&mut buf);
            push_object(&mut buf, "reaction", &self.v_keys, s.reactions);
            buf.push('}');
            self.write_raw(ch, s.t, buf.as_bytes());
        }
        self.buf = buf;
    }
}

/// Topic of the solver's conditioning warnings (schema `progmo.Warning`), one message per warning
/// at the time of its first crossing.
pub const WARNING_TOPIC: &str = "/progmo/warning";

impl<W: Write + Seek> SampleSink for McapSink<W> {
    fn sample(&mut self, s: &Sample<'_>) {
        if self.error.is_some() || self.writer.is_none() {
            return;
        }
        self.write_sample(s);
        self.last_t = s.t;
        if self.bodies.is_some() {
            self.write_bodies(s.t, s.q);
        }
    }

    fn warning(&mut self, w: &crate::solve::Warning) {
        if self.error.is_some() || self.writer.is_none() {
            return;
        }
        let ch = match self.warning_channel {
            Some(c) => c,
            None => {
                let schema = object_schema(
                    "progmo.Warning",
                    &[
                        ("kind", json!({"type": "string"})),
                        (
                            "rows",
                            json!({"type": "array", "items": {"type": "string"}}),
                        ),
                        ("value", json!({"type": "number"})),
                        ("threshold", json!({"type": "number"})),
                        ("message", json!({"type": "string"})),
                    ],
                );
                match self.add_json_channel(WARNING_TOPIC, "progmo.Warning", &schema) {
                    Ok(c) => {
                        self.warning_channel = Some(c);
                        c
                    }
                    Err(e) => {
                        self.error = Some(e);
                        return;
                    }
                }
            }
        };
        let msg = json!({"kind": w.kind.name(), "t": w.t, "rows": w.rows, "value": w.value,
                         "threshold": w.threshold, "message": w.to_string()});
        self.write_json(ch, w.t, &msg);
    }
}

impl<W: Write + Seek> OutputSink for McapSink<W> {
    /// Writes the summary section and footer, and flushes. Returns the first error met.
    fn finish(&mut self) -> Result<(), OutputError> {
        if let Some((bodies, Some(ch), _)) = &self.bodies {
            if let Some(update) = bodies.trace_update("progmo") {
                let ch = *ch;
                self.write_json(ch, self.last_t, &update);
            }
        }
        if let Some(mut w) = self.writer.take() {
            let r = w.finish();
            let mut inner = w.into_inner();
            if let Err(e) = r {
                self.error
                    .get_or_insert(OutputError::mcap(&self.file, "finish recording", e));
            } else if let Err(e) = inner.flush() {
                self.error
                    .get_or_insert(OutputError::io(&self.file, "flush", e));
            }
            self.done = Some(inner);
        }
        match &self.error {
            None => Ok(()),
            Some(e) => Err(e.replay()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::testutil::{feed, layout, sample_values};
    use std::io::Cursor;

    fn record(layout: &SampleLayout, n: usize) -> Vec<u8> {
        let mut sink = McapSink::new(Cursor::new(Vec::new()), layout, "<memory>").unwrap();
        feed(&mut sink, layout, n, 0.25);
        sink.frame_transform(
            0.25,
            "world",
            "body1",
            [1.0, 2.0, 3.0],
            [0.5, 0.5, -0.5, 0.5],
        );
        sink.frame_transform(1.5, "world", "body2", [0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0]);
        let extra = sink
            .add_json_channel("/extra", "test.Extra", &json!({"type": "object"}))
            .unwrap();
        sink.write_json(extra, 0.5, &json!({"k": 1}));
        sink.into_inner().unwrap().into_inner()
    }

    fn close(a: f64, b: f64) -> bool {
        a == b || (a - b).abs() <= 1e-15 * a.abs().max(b.abs())
    }

    #[test]
    #[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
    fn recording_reads_back() {
        let l = layout();
        let n = 6;
        let bytes = record(&l, n);

        let summary = mcap::Summary::read(&bytes)
            .unwrap()
            .expect("summary section");
        let stats = summary.stats.as_ref().unwrap();
        let topic_of = |id: &u16| summary.channels[id].topic.clone();
        let counts: BTreeMap<String, u64> = stats
            .channel_message_counts
            .iter()
            .map(|(id, c)| (topic_of(id), *c))
            .collect();
        let expect: BTreeMap<String, u64> = [
            ("/progmo/state", n as u64),
            ("/progmo/control", n as u64),
            ("/progmo/residual", n as u64),
            ("/progmo/reaction", n as u64),
            (FRAME_TRANSFORM_TOPIC, 2),
            ("/extra", 1),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        assert_eq!(counts, expect);
        assert_eq!(stats.message_count, 4 * n as u64 + 3);
        assert_eq!(stats.message_start_time, 0);
        assert_eq!(stats.message_end_time, 1_500_000_000);
        let mut schemas: Vec<(String, String, String)> = summary
            .channels
            .values()
            .map(|c| {
                let s = c.schema.as_ref().unwrap();
                (c.topic.clone(), s.name.clone(), s.encoding.clone())
            })
            .collect();
        schemas.sort();
        assert_eq!(
            schemas.iter().map(|s| s.1.as_str()).collect::<Vec<_>>(),
            [
                "test.Extra",
                "progmo.Control",
                "progmo.Reaction",
                "progmo.Residual",
                "progmo.State",
                "foxglove.FrameTransform"
            ]
        );
        assert!(schemas.iter().all(|s| s.2 == "jsonschema"));
        for c in summary.channels.values() {
            assert_eq!(c.message_encoding, "json");
            let schema: serde_json::Value =
                serde_json::from_slice(&c.schema.as_ref().unwrap().data).unwrap();
            assert!(schema.is_object());
        }

        let mut by_topic: BTreeMap<String, Vec<(u64, u32, serde_json::Value)>> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.log_time, m.publish_time);
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            by_topic
                .entry(m.channel.topic.clone())
                .or_default()
                .push((m.log_time, m.sequence, v));
        }
        let states = &by_topic["/progmo/state"];
        assert_eq!(states.len(), n);
        let k = 3;
        let (log, seq, msg) = &states[k];
        assert_eq!((*log, *seq), (750_000_000, k as u32));
        assert_eq!(msg["t"], 0.75);
        let vals = sample_values(&l, k);
        for (i, name) in l.q_names.iter().enumerate() {
            assert!(
                close(msg["q"][name].as_f64().unwrap(), vals[0][i]),
                "{name}"
            );
        }
        for (i, name) in l.v_names.iter().enumerate() {
            assert!(close(msg["v"][name].as_f64().unwrap(), vals[1][i]));
            assert!(close(msg["a"][name].as_f64().unwrap(), vals[2][i]));
        }
        let control = &by_topic["/progmo/control"][k].2;
        let residual = &by_topic["/progmo/residual"][k].2;
        let reaction = &by_topic["/progmo/reaction"][k].2;
        for (i, name) in l.v_names.iter().enumerate() {
            assert!(close(control["u"][name].as_f64().unwrap(), vals[3][i]));
            assert!(close(
                reaction["reaction"][name].as_f64().unwrap(),
                vals[4][i]
            ));
        }
        for (i, name) in l.row_names.iter().enumerate() {
            assert!(close(control["lambda"][name].as_f64().unwrap(), vals[5][i]));
            assert!(close(
                residual["residual"][name].as_f64().unwrap(),
                vals[6][i]
            ));
            assert!(close(
                residual["residual_rate"][name].as_f64().unwrap(),
                vals[7][i]
            ));
        }
        // Keys keep the layout order.
        let keys: Vec<&String> = msg["q"].as_object().unwrap().keys().collect();
        assert_eq!(keys.len(), l.q_names.len());

        let tf = &by_topic[FRAME_TRANSFORM_TOPIC];
        assert_eq!(tf[1].0, 1_500_000_000);
        assert_eq!(
            tf[0].2,
            json!({
                "timestamp": {"sec": 0, "nsec": 250_000_000},
                "parent_frame_id": "world",
                "child_frame_id": "body1",
                "translation": {"x": 1.0, "y": 2.0, "z": 3.0},
                "rotation": {"x": 0.5, "y": -0.5, "z": 0.5, "w": 0.5}
            })
        );
        assert_eq!(tf[1].2["timestamp"], json!({"sec": 1, "nsec": 500_000_000}));
        assert_eq!(by_topic["/extra"][0].2, json!({"k": 1}));
    }

    #[test]
    fn no_reaction_channel_without_reactions() {
        let l = layout().with_reactions(false);
        let mut sink = McapSink::new(Cursor::new(Vec::new()), &l, "<memory>").unwrap();
        feed(&mut sink, &l, 2, 0.1);
        let bytes = sink.into_inner().unwrap().into_inner();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let mut topics: Vec<String> = summary.channels.values().map(|c| c.topic.clone()).collect();
        topics.sort();
        assert_eq!(
            topics,
            ["/progmo/control", "/progmo/residual", "/progmo/state"]
        );
        assert_eq!(summary.stats.unwrap().message_count, 6);
    }

    #[test]
    fn non_finite_values_are_null() {
        let l = SampleLayout {
            q_names: vec!["x".into(), "y".into()],
            ..Default::default()
        };
        let mut sink = McapSink::new(Cursor::new(Vec::new()), &l, "<memory>").unwrap();
        sink.sample(&Sample {
            t: 2.0,
            q: &[f64::NAN, -0.0],
            v: &[],
            a: &[],
            u: &[],
            reactions: &[],
            lambda: &[],
            residual: &[],
            residual_rate: &[],
        });
        let bytes = sink.into_inner().unwrap().into_inner();
        let m = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .find(|m| m.channel.topic == "/progmo/state")
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        assert!(v["q"]["x"].is_null());
        assert_eq!(v["q"]["y"].as_f64().unwrap().to_bits(), (-0.0f64).to_bits());
        assert_eq!(m.log_time, 2_000_000_000);
    }

    /// A seekable writer that fails once `budget` bytes are written.
    struct Failing {
        inner: Cursor<Vec<u8>>,
        budget: usize,
    }
    impl Write for Failing {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if buf.len() > self.budget {
                return Err(std::io::Error::other("disk full"));
            }
            self.budget -= buf.len();
            self.inner.write(buf)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    impl Seek for Failing {
        fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
            self.inner.seek(pos)
        }
    }

    #[test]
    fn write_errors_are_kept_and_returned_by_finish() {
        let l = layout();
        let w = Failing {
            inner: Cursor::new(Vec::new()),
            budget: 50_000,
        };
        let mut sink = McapSink::new(w, &l, "full.mcap").unwrap();
        // Well beyond the budget (chunks are flushed at 1 MiB or at finish); must not panic.
        feed(&mut sink, &l, 5000, 0.001);
        sink.frame_transform(1.0, "a", "b", [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
        let err = sink.finish().unwrap_err().to_string();
        assert!(
            err.contains("full.mcap") && err.contains("disk full"),
            "{err}"
        );
        assert!(sink.finish().is_err());
    }

    #[test]
    fn log_times() {
        assert_eq!(log_time(0.0), 0);
        assert_eq!(log_time(1.0), 1_000_000_000);
        assert_eq!(log_time(0.1 + 0.2), 300_000_000);
        assert_eq!(log_time(-1.0), 0);
        assert_eq!(log_time(f64::NAN), 0);
    }

    #[test]
    fn file_recording_and_errors() {
        let l = layout();
        let path = std::env::temp_dir().join(format!("progmo-rec-{}.mcap", std::process::id()));
        let mut sink = McapSink::create(&path, &l).unwrap();
        feed(&mut sink, &l, 3, 0.1);
        sink.finish().unwrap();
        sink.finish().unwrap();
        // Samples after finish are ignored.
        sink.sample(&Sample {
            t: 0.0,
            q: &[],
            v: &[],
            a: &[],
            u: &[],
            reactions: &[],
            lambda: &[],
            residual: &[],
            residual_rate: &[],
        });
        drop(sink);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 12);

        // Dropping without finish still completes the file.
        let mut sink = McapSink::create(&path, &l).unwrap();
        feed(&mut sink, &l, 2, 0.1);
        drop(sink);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 8);

        let mut sink = McapSink::new(Cursor::new(Vec::new()), &l, "bad.mcap").unwrap();
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
        let err = sink.finish().unwrap_err().to_string();
        assert!(
            err.contains("bad.mcap") && err.contains("q has 1 values"),
            "{err}"
        );
        assert!(McapSink::create("/nonexistent-dir/x.mcap", &l).is_err());
    }
}
