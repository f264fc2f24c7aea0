//! FORMAT.md: bodies may be listed in any order and parameters in any order; the scene is the same.

use progmo::scene::Scene;
use std::path::Path;

const BODIES: [&str; 3] = [
    r#"
[[model.bodies]]
name = "upper"
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.001]
joints = [{ name = "q1", type = "hinge", axis = [0.0, 1.0, 0.0] }]
"#,
    r#"
[[model.bodies]]
name = "lower"
parent = "upper"
pos = [0.0, 0.0, -1.0]
mass = 1.0
com = [0.0, 0.0, -0.5]
inertia = [0.02, 0.02, 0.001]
joints = [{ name = "q2", type = "hinge", axis = [0.0, 1.0, 0.0] }]
"#,
    r#"
[[model.bodies]]
name = "tip"
parent = "lower"
pos = [0.0, 0.0, -1.0]
mass = 0.5
joints = [{ name = "q3", type = "slide", axis = [0.0, 0.0, 1.0] }]
"#,
];

fn scene(order: [usize; 3], params: &str) -> Scene {
    let bodies: String = order.iter().map(|&i| BODIES[i]).collect();
    let text = format!(
        r#"name = "order"
[parameters]
{params}

[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
{bodies}
[[programme]]
name = "p"
expr = "q1 - A*sin(w*t)"

[initial]
v = {{ q1 = "A*w" }}

[time]
t1 = 0.5
output_dt = 0.05
"#
    );
    Scene::from_text(Path::new("order.toml"), &text).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn children_before_parents_give_the_same_scene() {
    let params = "A = 0.1\nw = 2.0";
    let first = scene([0, 1, 2], params);
    let s1 = first.solve(&first.settings);
    assert!(s1.code.is_success(), "{:?}", s1.code);
    for order in [[2, 1, 0], [1, 2, 0], [2, 0, 1]] {
        let other = scene(order, params);
        assert_eq!(other.q_names(), first.q_names(), "{order:?}");
        let s2 = other.solve(&other.settings);
        assert_eq!(s2.trajectory, s1.trajectory, "{order:?}");
    }
}

#[test]
fn parameters_in_any_order_give_the_same_values() {
    let a = scene([0, 1, 2], "A = \"w/20\"\nw = 2.0");
    let b = scene([0, 1, 2], "w = 2.0\nA = \"w/20\"");
    assert_eq!(a.parameters, b.parameters);
    assert!(a.parameters.contains(&("A".to_string(), 0.1)));
}
