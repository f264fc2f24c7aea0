// The C++ anchor of `progmo bench`: Pinocchio's own algorithms, compiled against the headers that
// the `pin` wheel ships (header-only: no link to libpinocchio_default.so) plus Eigen, on the model
// and programme rows the Python side writes (bench/anchor.py). Built and run by the bench; see
// anchor.py for the protocol, the build command and the cache.
//
// Usage: anchor MODEL_FILE, then commands on stdin, one per line; answers on stdout:
//   check t q[nq] v[nv] J[s*nv] gamma[s]    ->  "a <variant> x1 .. xn" and "u <variant> ..." lines,
//                                               then "end"
//   bench iters t q[nq] v[nv] J[s*nv] gamma[s] -> "time <variant> seconds_per_call" lines (thread
//                                               CPU time of one loop of iters calls), then "end"
//   quit
// J and gamma are the programme rows in Pinocchio's convention (J a + gamma = 0) at (t, q, v); only
// the `kkt` variant uses them (the "given J, gamma" call); every `same_*` variant rebuilds J and
// gamma of the rows from the kinematics at (t, q, v), solves for dv/dt and forms u = J^T lambda,
// the work progmo's right-hand side does.
//
// Variants:
//   aba           aba(q, v, 0): unconstrained forward dynamics (no rows), the floor
//   kkt           forwardDynamics(q, v, 0, J, gamma): computeAllTerms + tree Cholesky KKT, J and
//                 gamma given (fixed), u = J^T lambda_c
//   same_cat      computeAllTerms(q, v) (M, nle, joint Jacobians, drift accelerations in one
//                 sweep) + frame Jacobian rows and classical drift + forwardDynamics(tau, J, gamma)
//                 on the computed terms + u
//   same_sep      forwardKinematics(q, v, 0) + computeJointJacobians + crba + nonLinearEffects +
//                 forwardDynamics(tau, J, gamma) + u (separate Pinocchio algorithms)
//   same_minv     forwardKinematics(q, v, 0) + aba (world convention: free acceleration) +
//                 computeMinverse from the ABA factorization (O(n^2)) + dense Schur complement + u
//   same_abaunit  forwardKinematics(q, v, 0) + aba for the free acceleration + s more ABA passes
//                 (zero gravity, zero velocity, tau = J_k^T) for M^-1 J^T: O(n s) + Schur + u
// Only when the rows hold one frame in all six directions (tip rows of axes 0-5 on one frame, the
// Panda's task), Pinocchio's O(n + m) constrained dynamics on that frame welded to the world
// (RigidConstraintModel CONTACT_6D, LOCAL, corrector gains 0, so the rows' time laws are left out:
// the same structure and size of work, the acceleration of the frame held at zero):
//   weld_kkt      forwardKinematics + joint Jacobians + crba + nonLinearEffects + the frame's LOCAL
//                 Jacobian and spatial drift + forwardDynamics(tau, J, gamma): the agreement reference
//   weld_cd       constraintDynamics (sparse constrained Cholesky)
//   weld_lcaba    lcaba (loop-constrained articulated-body algorithm)
// both with ProximalSettings(accuracy 1e-12, mu 1e-4, at most 10 iterations): lcaba's accuracy is
// bounded by its 1/mu conditioning (measured on the Panda against weld_kkt: mu 1e-4 -> 3e-12 in 5
// iterations, 1e-6 -> 3e-10, 1e-8 -> 7e-8; constraintDynamics 1e-13 with either).
// Pinocchio 4.1's lcaba adds into data.oa without clearing it first: a second call on the same Data
// returns a different (wrong) dv/dt (measured: alternately right and 7x off). weld_lcaba clears
// data.oa before each call, inside the timed work.
// Welded frames given by the model file ("welds M" after the rows, then M lines "weld J1 R1[9] P1[3]":
// the frame (R1, P1) of joint J1 welded to the world; a humanoid's soles) take the place of the
// six-row frame task: the weld_* variants hold all of them (weld_kkt stacks their Jacobians). A
// model file may then have "rows 0": the kkt and same_* variants (programme rows) are left out.
// Joint types: JointModelRX/RY/RZ, JointModelPX/PY/PZ and JointModelFreeFlyer (a floating base).
// Rows (model file, after the joints): "row joint K LAW AMP W" (coordinate K) or "row tip JOINT
// PX PY PZ AXIS LAW AMP W": component AXIS of the frame at P on JOINT, LOCAL_WORLD_ALIGNED (0-2 the
// origin's world position, 3-5 the world angular velocity: orientation rows held at acceleration
// level, d/dt w = 0); consecutive rows of one frame share one frame Jacobian and drift. LAW:
// one_minus_cos, sin, const, circle_cos, circle_sin (Row::fdd).
// Every call alternates between q and q + 1e-9 (as progmo's Scene.rhs_benchmark does) so nothing
// can be reused between calls.

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/contact-dynamics.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/loop-constrained-aba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <time.h>
#include <vector>

using namespace pinocchio;
using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

[[noreturn]] void fail(const std::string &msg) {
  std::fprintf(stderr, "anchor: error: %s\n", msg.c_str());
  std::exit(2);
}

struct Row {
  bool tip = false;   // tip: one component of a frame's motion; else a joint coordinate
  JointIndex joint = 0;  // tip: the parent joint of the frame
  SE3 placement = SE3::Identity();  // tip: the frame's origin in the joint frame
  int axis = 2;       // tip: 0, 1, 2 world position axis; 3, 4, 5 world angular axis
  int k = 0;          // joint row: velocity index
  // time law's second derivative: f(t) = c + amp (1 - cos w t), c + amp sin w t, constant, or
  // the circle laws r cos th(t), r sin th(t) with th = 2 pi t/T - sin(2 pi t/T) (amp = r, w = T)
  enum Law { ONE_MINUS_COS, SIN, CONST, CIRCLE_COS, CIRCLE_SIN } law = ONE_MINUS_COS;
  double amp = 0.0, w = 0.0;
  double fdd(double t) const {
    switch (law) {
      case ONE_MINUS_COS: return amp * w * w * std::cos(w * t);
      case SIN: return -amp * w * w * std::sin(w * t);
      case CONST: return 0.0;
      default: break;
    }
    const double W = 2.0 * M_PI / w, th = W * t - std::sin(W * t);
    const double thd = W * (1.0 - std::cos(W * t)), thdd = W * W * std::sin(W * t);
    return law == CIRCLE_COS ? -amp * (thd * thd * std::cos(th) + thdd * std::sin(th))
                             : amp * (thdd * std::cos(th) - thd * thd * std::sin(th));
  }
};

struct Anchor {
  Model model, model0;  // model0: zero gravity (unit-force ABA passes)
  std::vector<Row> rows;
  Data data, data0;
  int nv = 0, s = 0;
  // work space, allocated once
  MatrixXd J, Jf, MinvJt, S;
  VectorXd gamma, tau, zero, a, u, lambda, tmp;
  VectorXd damping;  // empty: no joint damping
  Eigen::LLT<MatrixXd> llt;
  // the welded frame of a six-row frame task (weld_* variants), when the rows hold one
  bool weld = false;
  std::vector<JointIndex> weld_joints;
  PINOCCHIO_STD_VECTOR_WITH_EIGEN_ALLOCATOR(SE3) weld_places;
  PINOCCHIO_STD_VECTOR_WITH_EIGEN_ALLOCATOR(RigidConstraintModel) cmodels;
  PINOCCHIO_STD_VECTOR_WITH_EIGEN_ALLOCATOR(RigidConstraintData) cdatas, cdatas_l;
  Data data_cd, data_l;
  ProximalSettings prox{1e-12, 1e-4, 10};
  MatrixXd Jw, Jf6;
  VectorXd gw;

  // tau = -damping v: the joint dampers' force, which Pinocchio's aba and forwardDynamics leave
  // out (model.damping is not read by them); progmo's right-hand side evaluates it too.
  const VectorXd &passive(const VectorXd &v) {
    if (damping.size()) tau.noalias() = -damping.cwiseProduct(v);
    return tau;
  }

  void load(const std::string &path) {
    std::ifstream in(path);
    if (!in) fail("cannot open " + path);
    std::string tag;
    int version = 0;
    in >> tag >> version;
    if (tag != "progmo-anchor" || version != 1) fail(path + ": not a progmo-anchor v1 model file");
    int njoints = 0;
    in >> tag >> njoints;
    if (tag != "joints" || njoints < 1) fail("expected 'joints N'");
    Eigen::Vector3d g;
    in >> tag >> g[0] >> g[1] >> g[2];
    if (tag != "gravity") fail("expected 'gravity gx gy gz'");
    for (int j = 0; j < njoints; ++j) {
      std::string type;
      long parent = 0;
      Eigen::Matrix3d R, I;
      Eigen::Vector3d p, c;
      double mass = 0;
      in >> tag >> type >> parent;
      if (tag != "joint") fail("expected 'joint TYPE PARENT ...'");
      for (int r = 0; r < 3; ++r)
        for (int cc = 0; cc < 3; ++cc) in >> R(r, cc);
      in >> p[0] >> p[1] >> p[2] >> mass >> c[0] >> c[1] >> c[2];
      for (int r = 0; r < 3; ++r)
        for (int cc = 0; cc < 3; ++cc) in >> I(r, cc);
      if (!in) fail("truncated joint record");
      const SE3 M(R, p);
      const std::string name = "j" + std::to_string(j + 1);
      JointIndex id;
      if (type == "JointModelRX") id = model.addJoint(parent, JointModelRX(), M, name);
      else if (type == "JointModelRY") id = model.addJoint(parent, JointModelRY(), M, name);
      else if (type == "JointModelRZ") id = model.addJoint(parent, JointModelRZ(), M, name);
      else if (type == "JointModelPX") id = model.addJoint(parent, JointModelPX(), M, name);
      else if (type == "JointModelPY") id = model.addJoint(parent, JointModelPY(), M, name);
      else if (type == "JointModelPZ") id = model.addJoint(parent, JointModelPZ(), M, name);
      else if (type == "JointModelFreeFlyer") id = model.addJoint(parent, JointModelFreeFlyer(), M, name);
      else fail("unsupported joint type " + type);
      model.appendBodyToJoint(id, Inertia(mass, c, Symmetric3(I)), SE3::Identity());
    }
    model.gravity.linear(g);
    in >> tag;
    if (tag == "damping") {  // optional: joint damping (a URDF's <dynamics damping>), per dof
      damping.setZero(model.nv);
      for (Eigen::Index i = 0; i < damping.size(); ++i) in >> damping[i];
      in >> tag;
    }
    in >> s;
    if (tag != "rows" || s < 0) fail("expected 'rows S'");
    for (int i = 0; i < s; ++i) {
      Row r;
      std::string kind, law;
      in >> tag >> kind;
      if (tag != "row") fail("expected 'row KIND ...'");
      if (kind == "tip") {
        long joint = 0;
        Eigen::Vector3d p;
        in >> joint >> p[0] >> p[1] >> p[2] >> r.axis;
        r.tip = true;
        r.joint = JointIndex(joint);
        r.placement = SE3(Eigen::Matrix3d::Identity(), p);
        if (joint < 1 || joint >= model.njoints || r.axis < 0 || r.axis > 5) fail("bad tip row");
      } else if (kind == "joint") {
        in >> r.k;
      } else {
        fail("unsupported row kind " + kind);
      }
      in >> law >> r.amp >> r.w;
      if (law == "one_minus_cos") r.law = Row::ONE_MINUS_COS;
      else if (law == "sin") r.law = Row::SIN;
      else if (law == "const") r.law = Row::CONST;
      else if (law == "circle_cos") r.law = Row::CIRCLE_COS;
      else if (law == "circle_sin") r.law = Row::CIRCLE_SIN;
      else fail("unsupported time law " + law);
      rows.push_back(r);
    }
    if (!in) fail("truncated row records");
    std::vector<std::pair<JointIndex, SE3>> given;
    if (in >> tag) {  // optional: welded frames
      int m = 0;
      in >> m;
      if (tag != "welds" || m < 1) fail("expected 'welds M'");
      for (int i = 0; i < m; ++i) {
        long joint = 0;
        Eigen::Matrix3d R;
        Eigen::Vector3d p;
        in >> tag >> joint;
        for (int r = 0; r < 3; ++r)
          for (int cc = 0; cc < 3; ++cc) in >> R(r, cc);
        in >> p[0] >> p[1] >> p[2];
        if (!in || tag != "weld" || joint < 1 || joint >= model.njoints) fail("bad weld record");
        given.emplace_back(JointIndex(joint), SE3(R, p));
      }
    }
    if (s == 0 && given.empty()) fail("a model file with no rows needs welds");
    nv = model.nv;
    for (const Row &r : rows)
      if (!r.tip && (r.k < 0 || r.k >= nv)) fail("joint row index out of range");
    model0 = model;
    model0.gravity.setZero();
    data = Data(model);
    data0 = Data(model0);
    J.setZero(s, nv);
    Jf.setZero(6, nv);
    MinvJt.setZero(nv, s);
    S.setZero(s, s);
    gamma.setZero(s);
    tau.setZero(nv);
    zero.setZero(nv);
    a.setZero(nv);
    u.setZero(nv);
    lambda.setZero(s);
    tmp.setZero(nv);
    llt = Eigen::LLT<MatrixXd>(s);
    if (given.empty()) find_weld();
    for (const auto &w : given) add_weld(w.first, w.second);
    if (weld) init_welds();
  }

  // Six consecutive tip rows of one frame with axes 0-5: that frame can be welded (weld_*).
  void find_weld() {
    for (int i = 0; i + 6 <= s && !weld; ++i) {
      int axes = 0;
      for (int k = i; k < i + 6; ++k) {
        const Row &r = rows[k];
        if (r.tip && r.joint == rows[i].joint && r.placement.isEqual(rows[i].placement)) axes |= 1 << r.axis;
      }
      if (axes == 63) add_weld(rows[i].joint, rows[i].placement);
    }
  }

  // One more frame welded to the world (RigidConstraintModel CONTACT_6D, LOCAL).
  void add_weld(JointIndex joint, const SE3 &place) {
    weld = true;
    weld_joints.push_back(joint);
    weld_places.push_back(place);
    cmodels.push_back(RigidConstraintModel(CONTACT_6D, model, joint, place, LOCAL));
    cdatas.push_back(RigidConstraintData(cmodels.back()));
    cdatas_l.push_back(RigidConstraintData(cmodels.back()));
  }

  void init_welds() {
    data_cd = Data(model);
    data_l = Data(model);
    initConstraintDynamics(model, data_cd, cmodels, cdatas);
    initConstraintDynamics(model, data_l, cmodels, cdatas_l);
    computeJointMinimalOrdering(model, data_l, cmodels);
    Jw.setZero(6 * cmodels.size(), nv);
    gw.setZero(6 * cmodels.size());
    Jf6.setZero(6, nv);
  }

  // J a + gamma = 0 on the welded frame's LOCAL spatial acceleration (what CONTACT_6D holds).
  void weld_kkt(const VectorXd &q, const VectorXd &v) {
    passive(v);
    forwardKinematics(model, data, q, v, zero);
    computeJointJacobians(model, data);
    crba(model, data, q, Convention::WORLD);
    nonLinearEffects(model, data, q, v);
    for (size_t k = 0; k < weld_joints.size(); ++k) {
      Jf6.setZero();
      getFrameJacobian(model, data, weld_joints[k], weld_places[k], LOCAL, Jf6);
      Jw.middleRows(6 * k, 6) = Jf6;
      gw.segment(6 * k, 6) = getFrameAcceleration(model, data, weld_joints[k], weld_places[k], LOCAL).toVector();
    }
    a = forwardDynamics(model, data, tau, Jw, gw, 0.0);
  }

  void weld_cd(const VectorXd &q, const VectorXd &v) {
    passive(v);
    a = constraintDynamics(model, data_cd, q, v, tau, cmodels, cdatas, prox);
  }

  void weld_lcaba(const VectorXd &q, const VectorXd &v) {
    passive(v);
    for (Motion &m : data_l.oa) m.setZero();
    a = lcaba(model, data_l, q, v, tau, cmodels, cdatas_l, prox);
  }

  // J and gamma of the rows at (t, q, v) from data.oMi, data.v, data.a (a = 0 drift) and data.J:
  // the caller ran the kinematics (and joint Jacobians) first.
  void rows_from_kinematics(double t) {
    const Row *last = nullptr;  // rows of one frame share its Jacobian and drift (one call each)
    Motion acc = Motion::Zero();
    for (int i = 0; i < s; ++i) {
      const Row &r = rows[i];
      if (r.tip) {
        if (!last || last->joint != r.joint || !last->placement.isEqual(r.placement)) {
          Jf.setZero();
          getFrameJacobian(model, data, r.joint, r.placement, LOCAL_WORLD_ALIGNED, Jf);
          acc = getFrameClassicalAcceleration(model, data, r.joint, r.placement, LOCAL_WORLD_ALIGNED);
          last = &r;
        }
        J.row(i) = Jf.row(r.axis);
        gamma[i] = (r.axis < 3 ? acc.linear()[r.axis] : acc.angular()[r.axis - 3]) - r.fdd(t);
      } else {
        J.row(i).setZero();
        J(i, r.k) = 1.0;
        gamma[i] = -r.fdd(t);
      }
    }
  }

  // a = a0 + MinvJt lambda, (J MinvJt) lambda = -(J a0 + gamma); u = J^T lambda.
  void schur(const VectorXd &a0) {
    S.noalias() = J * MinvJt;
    lambda.noalias() = -(J * a0);
    lambda -= gamma;
    llt.compute(S);
    llt.solveInPlace(lambda);
    a = a0;
    a.noalias() += MinvJt * lambda;
    u.noalias() = J.transpose() * lambda;
  }

  void same_cat(double t, const VectorXd &q, const VectorXd &v) {
    passive(v);
    computeAllTerms(model, data, q, v);
    rows_from_kinematics(t);
    a = forwardDynamics(model, data, tau, J, gamma, 0.0);
    u.noalias() = J.transpose() * data.lambda_c;
  }

  void same_sep(double t, const VectorXd &q, const VectorXd &v) {
    passive(v);
    forwardKinematics(model, data, q, v, zero);
    computeJointJacobians(model, data);
    rows_from_kinematics(t);
    crba(model, data, q, Convention::WORLD);
    nonLinearEffects(model, data, q, v);
    a = forwardDynamics(model, data, tau, J, gamma, 0.0);
    u.noalias() = J.transpose() * data.lambda_c;
  }

  void same_minv(double t, const VectorXd &q, const VectorXd &v) {
    passive(v);
    forwardKinematics(model, data, q, v, zero);
    computeJointJacobians(model, data);
    rows_from_kinematics(t);
    tmp = aba(model, data, q, v, tau, Convention::WORLD);
    computeMinverse(model, data);
    MinvJt.noalias() = data.Minv.selfadjointView<Eigen::Upper>() * J.transpose();
    schur(tmp);
  }

  void same_abaunit(double t, const VectorXd &q, const VectorXd &v) {
    passive(v);
    forwardKinematics(model, data, q, v, zero);
    computeJointJacobians(model, data);
    rows_from_kinematics(t);
    tmp = aba(model, data, q, v, tau);
    for (int i = 0; i < s; ++i) MinvJt.col(i) = aba(model0, data0, q, zero, J.row(i).transpose());
    schur(tmp);
  }

  void kkt(const VectorXd &q, const VectorXd &v, const MatrixXd &Jg, const VectorXd &gg) {
    passive(v);
    a = forwardDynamics(model, data, q, v, tau, Jg, gg);
    u.noalias() = Jg.transpose() * data.lambda_c;
  }
};

void print_vec(const char *what, const char *variant, const VectorXd &x) {
  std::printf("%s %s", what, variant);
  for (Eigen::Index i = 0; i < x.size(); ++i) std::printf(" %.17g", x[i]);
  std::printf("\n");
}

// CPU time of this thread (the machine is shared: wall time would count the time the process waits
// for a core); the Python side times progmo's Rust loop the same way (time.thread_time).
double thread_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

template <class F>
double time_loop(long iters, const VectorXd &q, F &&f) {
  VectorXd qb = q.array() + 1e-9;
  const VectorXd *states[2] = {&q, &qb};
  const double start = thread_seconds();
  for (long i = 0; i < iters; ++i) f(*states[i % 2]);
  return (thread_seconds() - start) / double(iters);
}

}  // namespace

int main(int argc, char **argv) {
  if (argc != 2) fail("usage: anchor MODEL_FILE (commands on stdin)");
  Anchor an;
  an.load(argv[1]);
  const int n = an.nv, nq = an.model.nq, s = an.s;  // nq > nv with a floating base (quaternion)
  std::printf("ready nv %d rows %d pinocchio %s eigen %d.%d.%d\n", n, s, PINOCCHIO_VERSION,
              EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION, EIGEN_MINOR_VERSION);
  std::fflush(stdout);
  std::string line;
  VectorXd q(nq), v(n), gg(s);
  MatrixXd Jg(s, n);
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string cmd;
    in >> cmd;
    if (cmd.empty()) continue;
    if (cmd == "quit") break;
    long iters = 0;
    if (cmd == "bench") in >> iters;
    else if (cmd != "check") fail("unknown command " + cmd);
    double t = 0;
    in >> t;
    for (int i = 0; i < nq; ++i) in >> q[i];
    for (int i = 0; i < n; ++i) in >> v[i];
    for (int i = 0; i < s; ++i)
      for (int j = 0; j < n; ++j) in >> Jg(i, j);
    for (int i = 0; i < s; ++i) in >> gg[i];
    if (!in) fail("truncated command " + cmd);
    if (cmd == "check") {
      print_vec("a", "aba", aba(an.model, an.data, q, v, an.passive(v)));
    }
    if (cmd == "check" && s > 0) {
      an.kkt(q, v, Jg, gg);
      print_vec("a", "kkt", an.a);
      print_vec("u", "kkt", an.u);
      an.same_cat(t, q, v);
      print_vec("a", "same_cat", an.a);
      print_vec("u", "same_cat", an.u);
      an.same_sep(t, q, v);
      print_vec("a", "same_sep", an.a);
      print_vec("u", "same_sep", an.u);
      an.same_minv(t, q, v);
      print_vec("a", "same_minv", an.a);
      print_vec("u", "same_minv", an.u);
      an.same_abaunit(t, q, v);
      print_vec("a", "same_abaunit", an.a);
      print_vec("u", "same_abaunit", an.u);
    }
    if (cmd == "check") {
      if (an.weld) {
        an.weld_kkt(q, v);
        print_vec("a", "weld_kkt", an.a);
        an.weld_cd(q, v);
        print_vec("a", "weld_cd", an.a);
        an.weld_lcaba(q, v);
        print_vec("a", "weld_lcaba", an.a);
      }
    } else {
      if (iters < 1) fail("bench needs iters >= 1");
      const double t_aba = time_loop(iters, q, [&](const VectorXd &x) {
        const VectorXd &r = aba(an.model, an.data, x, v, an.passive(v));
        asm volatile("" : : "g"(r.data()) : "memory");
      });
      std::printf("time aba %.9e\n", t_aba);
    }
    if (cmd == "bench" && s > 0) {
      const double t_kkt = time_loop(iters, q, [&](const VectorXd &x) {
        an.kkt(x, v, Jg, gg);
        asm volatile("" : : "g"(an.u.data()) : "memory");
      });
      const double t_cat = time_loop(iters, q, [&](const VectorXd &x) {
        an.same_cat(t, x, v);
        asm volatile("" : : "g"(an.u.data()) : "memory");
      });
      const double t_sep = time_loop(iters, q, [&](const VectorXd &x) {
        an.same_sep(t, x, v);
        asm volatile("" : : "g"(an.u.data()) : "memory");
      });
      const double t_minv = time_loop(iters, q, [&](const VectorXd &x) {
        an.same_minv(t, x, v);
        asm volatile("" : : "g"(an.u.data()) : "memory");
      });
      const double t_unit = time_loop(iters, q, [&](const VectorXd &x) {
        an.same_abaunit(t, x, v);
        asm volatile("" : : "g"(an.u.data()) : "memory");
      });
      std::printf("time kkt %.9e\ntime same_cat %.9e\ntime same_sep %.9e\n"
                  "time same_minv %.9e\ntime same_abaunit %.9e\n",
                  t_kkt, t_cat, t_sep, t_minv, t_unit);
    }
    if (cmd == "bench") {
      if (an.weld) {
        const double t_wcd = time_loop(iters, q, [&](const VectorXd &x) {
          an.weld_cd(x, v);
          asm volatile("" : : "g"(an.a.data()) : "memory");
        });
        const double t_wl = time_loop(iters, q, [&](const VectorXd &x) {
          an.weld_lcaba(x, v);
          asm volatile("" : : "g"(an.a.data()) : "memory");
        });
        const double t_wk = time_loop(iters, q, [&](const VectorXd &x) {
          an.weld_kkt(x, v);
          asm volatile("" : : "g"(an.a.data()) : "memory");
        });
        std::printf("time weld_cd %.9e\ntime weld_lcaba %.9e\ntime weld_kkt %.9e\n", t_wcd, t_wl, t_wk);
      }
    }
    std::printf("end\n");
    std::fflush(stdout);
  }
  return 0;
}
