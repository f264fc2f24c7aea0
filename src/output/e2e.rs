//! End-to-end: real problems through the writers (layouts always; solves once the integrators
//! are available).

use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::*;
use crate::model::Model;
use crate::problems::{particle, pendulum, rigid_body};
use crate::programme::Constraints;
use crate::solve::{solve_into, Problem, Settings, Solution, Trajectory};

#[test]
fn layouts_of_the_test_problems() {
    let top = SampleLayout::from_problem(&rigid_body::heavy_top());
    assert_eq!(top.q_names.len(), rigid_body::heavy_top().q0.len());
    assert_eq!(top.v_names.len(), rigid_body::heavy_top().v0.len());
    assert!(!top.reactions);
    assert!(!SampleLayout::from_problem(&particle::example_2_1()).reactions);
    assert!(!SampleLayout::from_problem(&pendulum::double_pendulum()).reactions);
    let rod = SampleLayout::from_problem(&pendulum::rod_and_swing());
    assert!(rod.reactions);
    assert_eq!(rod.row_names, ["rod", "swing"]);
    let sink = CsvSink::new(Vec::new(), &rod, "<memory>").unwrap();
    let h = sink.header();
    assert_eq!(
        h.iter().filter(|c| c.starts_with("reaction:")).count(),
        rod.v_names.len()
    );
}

/// Solve into CSV + MCAP + memory at once; None while the integrators are not available.
fn run<M: Model, C: Constraints>(
    problem: &Problem<M, C>,
) -> Option<(Solution, Trajectory, Vec<u8>, Vec<u8>)> {
    let layout = SampleLayout::from_problem(problem);
    let settings = Settings {
        output: crate::solve::Output::Every(0.05),
        ..Settings::default()
    };
    let csv = CsvSink::new(Vec::new(), &layout, "<memory>").unwrap();
    let rec = McapSink::new(Cursor::new(Vec::new()), &layout, "<memory>").unwrap();
    let mut sink = Progress::new(
        Tee::new(layout.trajectory(), Tee::new(csv, rec)),
        "e2e",
        problem.t0,
        problem.t1,
    )
    .enabled(false);
    let sol = catch_unwind(AssertUnwindSafe(|| {
        solve_into(problem, &settings, &mut sink)
    }))
    .ok()?;
    sink.finish().unwrap();
    let (mem, Tee { a: csv, b: rec }) = sink.into_inner().into_parts();
    Some((
        sol,
        mem,
        csv.into_inner().unwrap(),
        rec.into_inner().unwrap().into_inner(),
    ))
}

fn check<M: Model, C: Constraints>(problem: Problem<M, C>) {
    let Some((sol, mem, csv, rec)) = run(&problem) else {
        eprintln!("integrators not available: end-to-end check skipped");
        return;
    };
    assert!(mem.len() >= 2, "{:?}", sol.code);
    let back = read_csv_from(&csv[..], "<memory>").unwrap();
    // Bit-exact (reactions are zero in the CSV when the problem has none).
    let mut expect = mem.clone();
    if !SampleLayout::from_problem(&problem).reactions {
        expect.reactions.iter_mut().for_each(|r| *r = 0.0);
    }
    assert_eq!(back, expect);
    let summary = ::mcap::Summary::read(&rec).unwrap().unwrap();
    let stats = summary.stats.unwrap();
    let state = summary
        .channels
        .values()
        .find(|c| c.topic == "/progmo/state")
        .unwrap()
        .id;
    assert_eq!(stats.channel_message_counts[&state], mem.len() as u64);
    assert_eq!(
        stats.message_end_time,
        (mem.t[mem.len() - 1] * 1e9).round() as u64
    );

    let names = SampleLayout::from_problem(&problem).row_names;
    let v = summary_json(&SummaryInput {
        scene: "e2e",
        solution: &sol,
        row_names: &names,
        settings: &Settings::default(),
        wall_seconds: 0.0,
        git_revision: None,
        command_line: &[],
        servo: None,
        robot_file: None,
    })
    .unwrap();
    assert_eq!(v["code_name"], sol.code.name());
    assert_eq!(v["rows"].as_array().unwrap().len(), names.len());
}

#[test]
fn heavy_top_end_to_end() {
    check(rigid_body::heavy_top());
}

#[test]
fn rod_and_swing_end_to_end() {
    check(pendulum::rod_and_swing());
}
