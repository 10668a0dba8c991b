// The C++ floor of `make bench`: robofmu's chess-pd co-simulation loop written directly on
// Pinocchio's C++ API, with no FMI and no Python.
//
//   loop INPUT OUTPUT
//
// INPUT: the loop's numbers (benchmarks/loop_spec.py, written by benchmarks/floor.py), one per
// line: a key, then its values separated by blanks (a string key: the rest of the line).
// OUTPUT: the recorded rows of the last repeat, (n_steps + 1) x columns float64, row-major.
// stdout: one JSON object: the columns, the loop's time of every repeat (s), the step count.
//
// The four blocks are robofmu's (components/trajectory.py, components/ik/closed_form.py and
// base.py, components/blocks/ik.py, components/control.py, components/blocks/controller.py,
// components/plant.py, components/integrators.py, components/robots/serial.py), called in the
// order of system/replica.py InProcessDiagram.sampled: at each communication point every output
// (trajectory -> ik -> plant -> controller), a row recorded, then every block advanced over
// [t, t + h] with its inputs held. Floating-point operations follow robofmu's NumPy expressions
// term by term (left to right), so the trajectories agree to rounding.
//
// Nothing is allocated inside the timed loop: Pinocchio's Data, the Eigen vectors and the record
// are sized before it.

#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <Eigen/LU>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace pin = pinocchio;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// -- the input file -------------------------------------------------------------------------------
struct Input {
  std::map<std::string, std::vector<double>> numbers;
  std::map<std::string, std::string> strings;

  explicit Input(const char * path) {
    std::ifstream in(path);
    if (!in) throw std::runtime_error(std::string("cannot read ") + path);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream words(line);
      std::string key;
      if (!(words >> key) || key[0] == '#') continue;
      if (key.rfind("str:", 0) == 0) {
        std::string rest;
        std::getline(words >> std::ws, rest);
        strings[key.substr(4)] = rest;
        continue;
      }
      std::vector<double> values;
      std::string word;
      while (words >> word) values.push_back(std::strtod(word.c_str(), nullptr));  // "inf" too
      numbers[key] = values;
    }
  }
  const std::vector<double> & vec(const std::string & key, std::size_t size = 0) const {
    auto it = numbers.find(key);
    if (it == numbers.end()) throw std::runtime_error("input: missing " + key);
    if (size && it->second.size() != size)
      throw std::runtime_error("input: " + key + " needs " + std::to_string(size) + " values");
    return it->second;
  }
  double num(const std::string & key) const { return vec(key, 1)[0]; }
  const std::string & str(const std::string & key) const {
    auto it = strings.find(key);
    if (it == strings.end()) throw std::runtime_error("input: missing " + key);
    return it->second;
  }
};

// -- trajectory: LSPB moves through waypoints with pauses (components/trajectory.py) ----------------
struct Segment {
  double start, end;
  int from, to;  // waypoint rows
  bool move;
};

struct Trajectory {
  int m = 0;
  std::vector<double> w;  // waypoints, row-major (k + 1) x m
  std::vector<Segment> segments;
  std::vector<double> starts, breakpoints;
  double duration = 0, cruise = 1.5, tol = 1e-9, grip_close = INFINITY, grip_open = INFINITY;

  void setup(const Input & in) {
    const auto & d = in.vec("durations");
    const std::size_t k = d.size();
    m = static_cast<int>(in.num("task_dim"));
    w = in.vec("waypoints", (k + 1) * m);
    const double pause = in.num("pause");
    cruise = in.num("cruise_factor");
    double t = 0.0;
    for (std::size_t i = 0; i < k; ++i) {
      segments.push_back({t, t + d[i], int(i), int(i + 1), true});
      t += d[i];
      if (i < k - 1 && pause > 0.0) {
        segments.push_back({t, t + pause, int(i + 1), int(i + 1), false});
        t += pause;
      }
    }
    duration = t;
    for (const auto & s : segments) starts.push_back(s.start);
    breakpoints = in.vec("breakpoints");
    tol = in.num("snap_tolerance");
    grip_close = in.num("grip_close");
    grip_open = in.num("grip_open");
  }

  // snap_to: t moved onto a breakpoint within tol
  double snap(double t) const {
    const std::size_t k = std::lower_bound(breakpoints.begin(), breakpoints.end(), t) - breakpoints.begin();
    for (std::size_t j : {k - 1, k})  // k - 1 wraps for k = 0: out of range below
      if (j < breakpoints.size() && std::abs(breakpoints[j] - t) <= tol) return breakpoints[j];
    return t;
  }

  // WaypointTrajectory.evaluate(t, snap=True) into x, xd, xdd
  void evaluate(double t, double * x, double * xd, double * xdd) const {
    t = snap(t);
    if (t >= duration) {
      for (int i = 0; i < m; ++i) x[i] = w[(segments.back().to) * m + i], xd[i] = 0.0, xdd[i] = 0.0;
      return;
    }
    long i = long(std::upper_bound(starts.begin(), starts.end(), t) - starts.begin()) - 1;
    const Segment & s = segments[std::max(i, 0L)];
    const double * x0 = &w[s.from * m];
    if (!s.move) {
      for (int j = 0; j < m; ++j) x[j] = x0[j], xd[j] = 0.0, xdd[j] = 0.0;
      return;
    }
    const double * x1 = &w[s.to * m];
    lspb(x0, x1, s.end - s.start, t - s.start, x, xd, xdd);
  }

  void lspb(const double * x0, const double * x1, double T, double t, double * x, double * xd,
            double * xdd) const {
    t = std::min(std::max(t, 0.0), T);
    const double tb = T - T / cruise;
    for (int j = 0; j < m; ++j) {
      const double dx = x1[j] - x0[j];
      const double V = cruise * dx / T;
      const double a = V / tb;
      if (t < tb) {
        x[j] = x0[j] + 0.5 * a * t * t, xd[j] = a * t, xdd[j] = a;
      } else if (t <= T - tb) {
        x[j] = x0[j] + 0.5 * a * tb * tb + V * (t - tb), xd[j] = V, xdd[j] = 0.0;
      } else {
        const double r = T - t;
        x[j] = x0[j] + dx - 0.5 * a * r * r, xd[j] = a * r, xdd[j] = -a;
      }
    }
  }

  bool grip(double t) const {
    t = snap(t);
    const bool closed = t >= grip_close;
    const bool opened = t >= grip_open && grip_open > grip_close;
    return closed && !opened;
  }
};

// -- a robot model with a payload (components/robots/serial.py) -------------------------------------
struct Robot {
  pin::Model model;
  pin::Data data;
  pin::JointIndex payload_joint = 0;
  Eigen::Vector3d lever = Eigen::Vector3d::Zero();
  pin::Inertia bare;
  double payload = 0.0;

  Robot(const pin::Model & base, const Input & in) : model(base), data(model) {
    const auto & g = in.vec("gravity", 3);
    model.gravity.linear() << g[0], g[1], g[2];
    payload_joint = static_cast<pin::JointIndex>(in.num("payload_joint"));
    const auto & l = in.vec("payload_lever", 3);
    lever << l[0], l[1], l[2];
    bare = model.inertias[payload_joint];
  }

  void set_payload(double mass) {
    if (mass == payload) return;
    pin::Inertia inertia = bare;
    if (mass > 0.0) inertia += pin::Inertia(mass, lever, pin::Symmetric3::Zero());
    model.inertias[payload_joint] = inertia;
    payload = mass;
  }
};

// -- the IK block: pitch-elbow closed form and the rates (components/ik, components/blocks/ik.py) ---
struct IK {
  int n = 0, m = 0;
  Robot robot;
  pin::FrameIndex tcp;
  std::vector<int> axes;
  double a1, a2, a3, a4, phi, sign, axis_tol;
  VectorXd qd_limit, zero, rhs, q, qd, qdd, last, committed;
  bool has_last = false, has_committed = false, outside = false;
  pin::Data::Matrix6x J6;
  MatrixXd A;
  Eigen::PartialPivLU<MatrixXd> lu;
  long unreachable = 0;  // excursions (robofmu warns once for each)

  IK(const pin::Model & base, const Input & in) : robot(base, in) {
    n = base.nv;
    const auto & ax = in.vec("task_axes");
    for (double a : ax) axes.push_back(int(a));
    m = int(axes.size());
    if (n != 4 || m != 3) throw std::runtime_error("pitch_elbow IK: needs 4 joints and 3 task coordinates");
    tcp = base.getFrameId(in.str("tcp_frame"));
    if (tcp >= base.frames.size()) throw std::runtime_error("no frame " + in.str("tcp_frame"));
    a1 = in.num("a1"), a2 = in.num("a2"), a3 = in.num("a3"), a4 = in.num("a4");
    phi = in.num("tool_pitch"), sign = in.num("elbow_sign"), axis_tol = in.num("axis_tolerance");
    const auto & lim = in.vec("qd_limit", n);
    qd_limit = Eigen::Map<const VectorXd>(lim.data(), n);
    zero = VectorXd::Zero(n);
    rhs.resize(n), q.resize(n), qd.resize(n), qdd.resize(n), last.resize(n), committed.resize(n);
    J6 = pin::Data::Matrix6x::Zero(6, n);
    A = MatrixXd::Zero(n, n);
    A.row(m) << 0.0, 1.0, 1.0, 1.0;  // the constraint row: q2 + q3 + q4 = tool pitch
    lu = Eigen::PartialPivLU<MatrixXd>(n);
  }

  void reset() { has_last = has_committed = outside = false; unreachable = 0; }

  // PitchElbowIK.position; false: unreachable
  bool position(const double * x) {
    const double px = x[0], py = x[1], pz = x[2];
    const double p = std::hypot(px, py);
    if (p < axis_tol) return false;
    const double pw = p - a4 * std::cos(phi);
    const double r = pz - a4 * std::sin(phi) - a1;
    const double d = std::hypot(pw, r);
    const double c = d > 0 ? (std::pow(a2, 2.0) + d * d - std::pow(a3, 2.0)) / (2.0 * a2 * d) : 2.0;
    if (!(std::abs(c) < 1.0 - 1e-12)) return false;
    const double q2 = std::atan2(r, pw) + sign * std::acos(c);
    const double q23 = std::atan2(r - a2 * std::sin(q2), pw - a2 * std::cos(q2));
    q << std::atan2(py, px), q2, q23 - q2, phi - q23;
    return true;
  }

  // IKSolver.rates: A = [J; C], qd = A^-1 [xd; 0], qdd = A^-1 [xdd - Jdot qd; 0]
  bool rates(const double * xd, const double * xdd) {
    pin::Model & model = robot.model;
    pin::Data & data = robot.data;
    J6.setZero();
    pin::computeFrameJacobian(model, data, q, tcp, pin::LOCAL_WORLD_ALIGNED, J6);
    for (int i = 0; i < m; ++i) A.row(i) = J6.row(axes[i]);
    lu.compute(A);
    for (int i = 0; i < m; ++i) rhs[i] = xd[i];
    rhs.tail(n - m).setZero();
    qd = lu.solve(rhs);
    pin::forwardKinematics(model, data, q, qd, zero);
    const pin::Motion jdot_qd = pin::getFrameClassicalAcceleration(model, data, tcp, pin::LOCAL_WORLD_ALIGNED);
    for (int i = 0; i < m; ++i) rhs[i] = xdd[i] - jdot_qd.linear()[axes[i]];
    rhs.tail(n - m).setZero();
    qdd = lu.solve(rhs);
    return std::isfinite(qd.sum() + qdd.sum());
  }

  // IKBlock.output into q_ref, qd_ref, qdd_ref; returns reachable
  bool output(const double * x, const double * xd, const double * xdd, double * q_ref, double * qd_ref,
              double * qdd_ref) {
    bool ok = position(x) && rates(xd, xdd);
    if (ok) {
      double top = -1.0;  // the largest |qd| / qd_limit (robofmu: ratio[argmax] > 1 refuses)
      for (int j = 0; j < n; ++j) top = std::max(top, std::abs(qd[j]) / qd_limit[j]);
      ok = !(top > 1.0);
    }
    if (!ok) {
      if (!outside) ++unreachable, outside = true;
      for (int j = 0; j < n; ++j) q_ref[j] = has_last ? last[j] : 0.0, qd_ref[j] = 0.0, qdd_ref[j] = 0.0;
      return false;
    }
    outside = false;
    last = q, has_last = true;
    for (int j = 0; j < n; ++j) q_ref[j] = q[j], qd_ref[j] = qd[j], qdd_ref[j] = qdd[j];
    return true;
  }

  void advance() { committed = last, has_committed = has_last; }  // (closed form: not used)
};

// -- the controller block: computed torque on its own model (components/control.py) -----------------
struct Controller {
  int n;
  Robot robot;
  double kp, kd, ki, payload_mass;
  VectorXd z, q, qd, u;

  Controller(const pin::Model & base, const Input & in) : robot(base, in) {
    n = base.nv;
    kp = in.num("kp"), kd = in.num("kd"), ki = in.num("ki");
    payload_mass = in.num("controller_payload_mass");
    z = VectorXd::Zero(n), q.resize(n), qd.resize(n), u.resize(n);
  }

  void reset() { z.setZero(); robot.set_payload(0.0); }

  void output(const double * q_ref, const double * qd_ref, const double * qdd_ref, const double * q_in,
              const double * qd_in, bool grip, double * tau) {
    robot.set_payload(grip ? payload_mass : 0.0);
    for (int j = 0; j < n; ++j) {
      q[j] = q_in[j], qd[j] = qd_in[j];
      u[j] = qdd_ref[j] + kd * (qd_ref[j] - qd_in[j]) + kp * (q_ref[j] - q_in[j]) + ki * z[j];
    }
    const VectorXd & t = pin::rnea(robot.model, robot.data, q, qd, u);
    for (int j = 0; j < n; ++j) tau[j] = t[j];
  }

  void advance(const double * q_ref, const double * q_in, double h) {
    for (int j = 0; j < n; ++j) z[j] += (q_ref[j] - q_in[j]) * h;
  }
};

// -- the plant block: RK4 of x' = (qd, aba(q, qd, tau)) (components/plant.py, integrators.py) --------
struct Plant {
  int n;
  Robot robot;
  double payload_mass, max_substep;
  bool grip = false;
  VectorXd q0, qd0, q, qd, tau;
  VectorXd xq, xv, k1q, k1v, k2q, k2v, k3q, k3v, k4q, k4v;

  Plant(const pin::Model & base, const Input & in) : robot(base, in) {
    n = base.nv;
    payload_mass = in.num("plant_payload_mass");
    max_substep = in.num("max_substep");
    const auto & a = in.vec("q0", n);
    const auto & b = in.vec("qd0", n);
    q0 = Eigen::Map<const VectorXd>(a.data(), n);
    qd0 = Eigen::Map<const VectorXd>(b.data(), n);
    for (VectorXd * v : {&q, &qd, &tau, &xq, &xv, &k1q, &k1v, &k2q, &k2v, &k3q, &k3v, &k4q, &k4v}) v->resize(n);
    reset();
  }

  void reset() { q = q0, qd = qd0, grip = false, robot.set_payload(0.0); }

  void set_grip(bool closed) {
    if (closed == grip) return;
    grip = closed;
    robot.set_payload(grip ? payload_mass : 0.0);
  }

  // f(x) = (qd, aba(q, qd, tau)) into (dq, dv). Through Eigen::Ref, the argument type of
  // libpinocchio_default's explicit instantiation (the one Pinocchio's Python binding calls).
  void f(const VectorXd & xq_, const VectorXd & xv_, VectorXd & dq, VectorXd & dv) {
    const Eigen::Ref<const VectorXd> rq(xq_), rv(xv_), rt(tau);
    dq = xv_;
    dv = pin::aba(robot.model, robot.data, rq, rv, rt, pin::Convention::LOCAL);
  }

  bool advance(const double * tau_in, bool grip_in, double h) {
    set_grip(grip_in);
    for (int j = 0; j < n; ++j) tau[j] = tau_in[j];
    const int steps = std::max(1, int(std::ceil(h / max_substep - 1e-9)));
    const double dt = h / steps;
    const double half = 0.5 * dt;
    const double sixth = dt / 6.0;
    for (int s = 0; s < steps; ++s) {
      f(q, qd, k1q, k1v);
      for (int j = 0; j < n; ++j) xq[j] = q[j] + half * k1q[j], xv[j] = qd[j] + half * k1v[j];
      f(xq, xv, k2q, k2v);
      for (int j = 0; j < n; ++j) xq[j] = q[j] + half * k2q[j], xv[j] = qd[j] + half * k2v[j];
      f(xq, xv, k3q, k3v);
      for (int j = 0; j < n; ++j) xq[j] = q[j] + dt * k3q[j], xv[j] = qd[j] + dt * k3v[j];
      f(xq, xv, k4q, k4v);
      for (int j = 0; j < n; ++j) {
        q[j] = q[j] + sixth * (k1q[j] + 2.0 * k2q[j] + 2.0 * k3q[j] + k4q[j]);
        qd[j] = qd[j] + sixth * (k1v[j] + 2.0 * k2v[j] + 2.0 * k3v[j] + k4v[j]);
      }
    }
    return std::isfinite(q.sum() + qd.sum());
  }
};

int main(int argc, char ** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s INPUT OUTPUT\n", argv[0]);
    return 2;
  }
  try {
    const Input in(argv[1]);
    pin::Model base;
    pin::urdf::buildModel(in.str("urdf"), base);
    if (base.nq != base.nv) throw std::runtime_error("only revolute and prismatic joints are supported");
    const int n = base.nv;
    const double h = in.num("h");
    const long N = long(in.num("n_steps"));
    const int repeats = std::max(1, int(in.num("repeats")));

    Trajectory trajectory;
    trajectory.setup(in);
    const int m = trajectory.m;
    IK ik(base, in);
    Plant plant(base, in);
    Controller controller(base, in);

    // the record: robofmu's columns (every output; Reals, then Booleans, in evaluation order)
    std::vector<std::string> columns;
    auto add = [&](const std::string & base_name, int size) {
      for (int i = 1; i <= size; ++i) columns.push_back(base_name + "[" + std::to_string(i) + "]");
    };
    add("trajectory.x_ref", m), add("trajectory.xd_ref", m), add("trajectory.xdd_ref", m);
    add("ik.q_ref", n), add("ik.qd_ref", n), add("ik.qdd_ref", n);
    add("plant.q", n), add("plant.qd", n), add("controller.tau", n);
    columns.push_back("trajectory.grip"), columns.push_back("ik.reachable");
    const std::size_t width = columns.size();
    std::vector<double> record((N + 1) * width);

    // the signals (each block's output slots) and times as robofmu's master keeps them
    std::vector<double> x(m), xd(m), xdd(m), q_ref(n), qd_ref(n), qdd_ref(n), q(n), qd(n), tau(n);
    std::vector<double> loops;
    bool diverged = false;
    for (int rep = 0; rep < repeats; ++rep) {
      ik.reset(), plant.reset(), controller.reset();
      const auto start = std::chrono::steady_clock::now();
      double t_block = 0.0;  // the blocks' time: t_k + h after a step, as in a FMU
      for (long k = 0; k <= N; ++k) {
        // evaluate: trajectory -> ik -> plant -> controller
        trajectory.evaluate(t_block, x.data(), xd.data(), xdd.data());
        const bool grip = trajectory.grip(t_block);
        const bool reachable = ik.output(x.data(), xd.data(), xdd.data(), q_ref.data(), qd_ref.data(), qdd_ref.data());
        for (int j = 0; j < n; ++j) q[j] = plant.q[j], qd[j] = plant.qd[j];
        controller.output(q_ref.data(), qd_ref.data(), qdd_ref.data(), q.data(), qd.data(), grip, tau.data());
        // record
        double * row = &record[k * width];
        for (const auto * v : {&x, &xd, &xdd, &q_ref, &qd_ref, &qdd_ref, &q, &qd, &tau})
          row = std::copy(v->begin(), v->end(), row);
        *row++ = grip ? 1.0 : 0.0;
        *row++ = reachable ? 1.0 : 0.0;
        if (k == N) break;
        // advance every block over [t_k, t_k + h], inputs held
        const double t = h * double(k);
        ik.advance();
        if (!plant.advance(tau.data(), grip, h)) {
          diverged = true;
          break;
        }
        controller.advance(q_ref.data(), q.data(), h);
        t_block = t + h;
      }
      loops.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      if (diverged) break;
    }
    if (diverged) throw std::runtime_error("the plant's state became non-finite");

    std::FILE * out = std::fopen(argv[2], "wb");
    if (!out || std::fwrite(record.data(), sizeof(double), record.size(), out) != record.size())
      throw std::runtime_error(std::string("cannot write ") + argv[2]);
    std::fclose(out);

    std::printf("{\"n_steps\": %ld, \"width\": %zu, \"unreachable\": %ld, \"loops\": [", N, width, ik.unreachable);
    for (std::size_t i = 0; i < loops.size(); ++i) std::printf("%s%.9g", i ? ", " : "", loops[i]);
    std::printf("], \"columns\": [");
    for (std::size_t i = 0; i < width; ++i) std::printf("%s\"%s\"", i ? ", " : "", columns[i].c_str());
    std::printf("], \"eigen\": \"%d.%d.%d\", \"pinocchio\": \"%s\"}\n", EIGEN_WORLD_VERSION,
                EIGEN_MAJOR_VERSION, EIGEN_MINOR_VERSION, PINOCCHIO_VERSION);
    return 0;
  } catch (const std::exception & e) {
    std::fprintf(stderr, "loop: %s\n", e.what());
    return 1;
  }
}
