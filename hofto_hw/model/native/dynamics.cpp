// The tick's rigid-body dynamics as plain C functions: pinocchio's own algorithms (CRBA,
// gravity, nonlinear effects, the sparse Cholesky of M, ABA as its fallback, RNEA), and one
// recursion of ours for Cᵀ·qd (ct_qd_of: pinocchio has it only as the whole Coriolis matrix),
// on a copy of the robot's pinocchio model, called from numba kernels
// (hofto_hw/model/kernels.py) so that a snapshot or a feed-forward is one Python->compiled
// call. Built at install time by setup.py (into the wheel), loaded by
// hofto_hw/model/native/__init__.py.
//
// Compile time is the reason for ArmJointsTpl (pinocchio's documented extension point: a Model
// over one's own joint collection): pinocchio's default collection (~25 joint types in one
// boost::variant) makes every algorithm instantiate ~25 visitors (4 min to build here); an arm
// needs the revolute joints (RobotModel refuses nq != nv; other joints: the Python path runs).
// The collection has no mimic joint: pinocchio's Model and Data look for one with boost::get,
// which BOOST_VARIANT_USE_RELAXED_GET_BY_DEFAULT lets answer "none" for a type outside the
// variant (with the mimic joint inside, every visitor recursed into it: twice the build time).
//
// ABI: every function is extern "C" with integers and pointers only; the "hofto_dyn1_" prefix
// carries the ABI version (numba's cached kernels bind these names).

#ifndef BOOST_VARIANT_USE_RELAXED_GET_BY_DEFAULT
  #define BOOST_VARIANT_USE_RELAXED_GET_BY_DEFAULT
#endif
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/cholesky.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <algorithm>
#include <cstdint>
#include <exception>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace hofto_native
{
  template<typename _Scalar, int _Options>
  struct ArmJointsTpl
  {
    typedef _Scalar Scalar;
    static constexpr int Options = _Options;

    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 0> JointModelRX;
    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 1> JointModelRY;
    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 2> JointModelRZ;
    typedef pinocchio::JointModelRevoluteUnalignedTpl<Scalar, Options> JointModelRevoluteUnaligned;
    // named by pinocchio's Model and Data; not a member of the variant (see above)
    typedef pinocchio::JointModelMimicTpl<Scalar, Options, ArmJointsTpl> JointModelMimic;

    typedef boost::variant<
      JointModelRX,
      JointModelRY,
      JointModelRZ,
      JointModelRevoluteUnaligned>
      JointModelVariant;

    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 0> JointDataRX;
    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 1> JointDataRY;
    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 2> JointDataRZ;
    typedef pinocchio::JointDataRevoluteUnalignedTpl<Scalar, Options> JointDataRevoluteUnaligned;
    typedef pinocchio::JointDataMimicTpl<Scalar, Options, ArmJointsTpl> JointDataMimic;

    typedef boost::variant<
      JointDataRX,
      JointDataRY,
      JointDataRZ,
      JointDataRevoluteUnaligned>
      JointDataVariant;
  };

  typedef ArmJointsTpl<double, 0> Joints;
  typedef pinocchio::ModelTpl<double, 0, ArmJointsTpl> Model;
  typedef pinocchio::DataTpl<double, 0, ArmJointsTpl> Data;
  typedef pinocchio::JointModelTpl<double, 0, ArmJointsTpl> JointModel;
  typedef Eigen::Map<const Eigen::VectorXd> In;

  struct Handle
  {
    Model model;
    Data data;
    Eigen::Index n;
    // per joint (index 1..n): the rotation axis in the joint's frame, constant for the
    // revolute joints of ArmJointsTpl, and the subtree momentum (scratch of ct_qd_of)
    std::vector<Eigen::Vector3d> axis;
    std::vector<pinocchio::Force> momentum; // C++17: aligned by std::allocator
    explicit Handle(const Model & m)
    : model(m)
    , data(model)
    , n(model.nv)
    , axis(model.joints.size(), Eigen::Vector3d::Zero())
    , momentum(model.joints.size(), pinocchio::Force::Zero())
    {
      pinocchio::forwardKinematics(model, data, pinocchio::neutral(model));
      for (std::size_t i = 1; i < model.joints.size(); ++i)
        axis[i] = data.joints[i].S().matrix().template bottomRows<3>().col(0);
    }
  };

  // joint kinds, as hofto_hw/model/native/__init__.py writes them
  enum Kind : std::int64_t
  {
    RX = 0,
    RY,
    RZ,
    R_UNALIGNED
  };

  JointModel joint_of(std::int64_t kind, const double * axis)
  {
    const Eigen::Vector3d a(axis[0], axis[1], axis[2]);
    switch (kind)
    {
    case RX:
      return JointModel(Joints::JointModelRX());
    case RY:
      return JointModel(Joints::JointModelRY());
    case RZ:
      return JointModel(Joints::JointModelRZ());
    case R_UNALIGNED:
      return JointModel(Joints::JointModelRevoluteUnaligned(a));
    default:
      throw std::invalid_argument("unknown joint kind");
    }
  }

  // terms of hofto_dyn1_terms (the snapshot's Needs without friction)
  enum Terms : std::int64_t
  {
    MASS = 1,
    GRAVITY = 2,
    NLE = 4,
    CORIOLIS_T = 8,
    ACCEL = 16
  };

  // M⁻¹·(total − nle) into ddq by pinocchio's sparse Cholesky (U·D·Uᵀ) of data.M, which crba
  // has just filled: the acceleration ABA gives, without ABA's three passes over the tree.
  // False (ddq unspecified) when a pivot is not positive and finite: M is not numerically
  // positive definite, and the caller runs ABA instead.
  bool accel_by_mass(
    Handle & h, const double * total, const Eigen::VectorXd & nle, Eigen::Map<Eigen::VectorXd> ddq)
  {
    pinocchio::cholesky::decompose(h.model, h.data);
    const Eigen::VectorXd & D = h.data.D;
    for (Eigen::Index j = 0; j < h.n; ++j)
      if (!(D[j] > 0.0 && D[j] < std::numeric_limits<double>::infinity()))
        return false;
    ddq = In(total, h.n) - nle;
    pinocchio::cholesky::solve(h.model, h.data, ddq);
    return true;
  }

  // C(q,qd)ᵀ·qd into out (n) without the Coriolis matrix: with Ṁ = C + Cᵀ (pinocchio's C),
  // Cᵀ·qd = Ṁ·qd − C·qd = ∂T/∂q for the kinetic energy T = ½·qdᵀ·M(q)·qd, and for a tree of
  // revolute joints ∂T/∂q_k = −S_kᵀ·(v_k ×* H_k): S_k joint k's axis, v_k body k's spatial
  // velocity, H_k the momentum of the bodies joint k carries (its subtree), all in body k's
  // frame. One backward pass over data.v and data.liMi, which `kinematics` says are those of
  // (q, qd) already (nonLinearEffects leaves them so); otherwise forwardKinematics first.
  // Cheaper than computeCoriolisMatrix (~0.4 against ~1.8 µs), and it sums momenta, never
  // inertias (no clamped composite mass).
  void ct_qd_of(Handle & h, const In & Q, const In & V, bool kinematics, double * out)
  {
    const Model & model = h.model;
    Data & data = h.data;
    if (!kinematics)
      pinocchio::forwardKinematics(model, data, Q, V);
    const std::size_t nj = model.joints.size();
    for (std::size_t i = 1; i < nj; ++i)
      h.momentum[i] = model.inertias[i] * data.v[i];
    for (std::size_t i = nj - 1; i > 0; --i)
    {
      const pinocchio::Motion & v = data.v[i];
      const pinocchio::Force & H = h.momentum[i];
      // the angular part of v ×* H
      const Eigen::Vector3d t = v.angular().cross(H.angular()) + v.linear().cross(H.linear());
      out[model.joints[i].idx_v()] = -h.axis[i].dot(t);
      const std::size_t parent = model.parents[i];
      if (parent > 0)
        h.momentum[parent] += data.liMi[i].act(H);
    }
  }

  // hofto_dyn1_terms' work. The acceleration takes the same arithmetic whatever else is asked
  // for: an observer's estimate must not depend on which other observers share the snapshot
  // (HOFTO's gains, ~1e10, turn a rounding difference in the acceleration into 1e-10 N·m).
  // nle is never C·qd + g from the Coriolis matrix (not nle when identified link masses of
  // both signs cancel: pinocchio clamps summed masses).
  void terms_of(
    Handle & h,
    std::int64_t terms,
    const double * q,
    const double * qd,
    const double * total,
    double * out)
  {
    const Eigen::Index n = h.n;
    const In Q(q, n), V(qd, n);
    double * row = out + n * n;
    Eigen::Map<Eigen::VectorXd> g(row, n), nle(row + n, n), ddq(row + 2 * n, n);
    const bool accel = terms & ACCEL;
    if ((terms & MASS) || accel)
      pinocchio::crba(h.model, h.data, Q);
    if (terms & MASS)
    {
      const Eigen::MatrixXd & M = h.data.M; // the upper triangle is CRBA's
      for (Eigen::Index i = 0; i < n; ++i)
        for (Eigen::Index k = 0; k < n; ++k)
          out[i * n + k] = k >= i ? M(i, k) : M(k, i);
    }
    if (terms & GRAVITY)
    {
      pinocchio::computeGeneralizedGravity(h.model, h.data, Q);
      g = h.data.g;
    }
    // the nonlinear effects: into their row when asked for, and for the solve
    const bool nle_ran = (terms & NLE) || accel;
    if (nle_ran)
      pinocchio::nonLinearEffects(h.model, h.data, Q, V);
    if (terms & NLE)
      nle = h.data.nle;
    if (terms & CORIOLIS_T)
      ct_qd_of(h, Q, V, nle_ran, row + 3 * n);
    if (accel && !accel_by_mass(h, total, h.data.nle, ddq))
    {
      pinocchio::aba(h.model, h.data, Q, V, In(total, n));
      ddq = h.data.ddq;
    }
  }
} // namespace hofto_native

using namespace hofto_native;

// What the library was built from (setup.py defines HOFTO_DYN_SOURCE_SHA256, the source's
// hash): checked when it is loaded (hofto_hw/model/native/__init__.py).
#ifndef HOFTO_DYN_SOURCE_SHA256
  #define HOFTO_DYN_SOURCE_SHA256 "unknown"
#endif

extern "C" {

// The pinocchio version whose headers this library was compiled from: major, minor, patch.
void hofto_dyn1_pinocchio_version(std::int64_t * out)
{
  out[0] = PINOCCHIO_MAJOR_VERSION;
  out[1] = PINOCCHIO_MINOR_VERSION;
  out[2] = PINOCCHIO_PATCH_VERSION;
}

// The SHA-256 of dynamics.cpp as it was compiled (hex).
const char * hofto_dyn1_source_sha256()
{
  return HOFTO_DYN_SOURCE_SHA256;
}

// A model of n joints, joint j's parent parent[j] (0 = the base, else a joint 1..n), kind[j]
// (Kind), axis[3j..] (unaligned kinds), placement[12j..] (rotation row-major, then
// translation [m]), inertia[10j..] (mass [kg], centre of mass (3) [m], rotational inertia
// about it xx, xy, yy, xz, yz, zz [kg m^2]), armature[j] [kg m^2], gravity (3) [m/s^2].
// Returns the handle, or null when the numbers do not make a model.
void * hofto_dyn1_create(
  std::int64_t n,
  const std::int64_t * parent,
  const std::int64_t * kind,
  const double * axis,
  const double * placement,
  const double * inertia,
  const double * armature,
  const double * gravity)
{
  try
  {
    Model model;
    for (std::int64_t j = 0; j < n; ++j)
    {
      const double * p = placement + 12 * j;
      Eigen::Matrix3d R;
      R << p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8];
      const pinocchio::SE3 M(R, Eigen::Vector3d(p[9], p[10], p[11]));
      const auto id = model.addJoint(
        static_cast<Model::JointIndex>(parent[j]), joint_of(kind[j], axis + 3 * j), M,
        "joint" + std::to_string(j + 1));
      const double * I = inertia + 10 * j;
      model.inertias[id] = pinocchio::Inertia(
        I[0], Eigen::Vector3d(I[1], I[2], I[3]),
        pinocchio::Symmetric3(I[4], I[5], I[6], I[7], I[8], I[9]));
    }
    if (model.nv != n || model.nq != n)
      return nullptr;
    model.armature = Eigen::Map<const Eigen::VectorXd>(armature, n);
    model.gravity.linear(Eigen::Vector3d(gravity[0], gravity[1], gravity[2]));
    return new Handle(model);
  }
  catch (const std::exception &)
  {
    return nullptr;
  }
}

void hofto_dyn1_destroy(void * handle)
{
  delete static_cast<Handle *>(handle);
}

// Joint `joint`'s (0-based) link inertia := inertia[0..9] (the layout of hofto_dyn1_create),
// in place: the handle, its Data and every address the kernels hold stay (a payload swapped
// in between two ticks, hofto_hw/model/payload.py LinkSwap). 0, or -1 for no such joint.
std::int64_t hofto_dyn1_set_inertia(void * handle, std::int64_t joint, const double * inertia)
{
  Handle & h = *static_cast<Handle *>(handle);
  if (joint < 0 || joint >= h.n)
    return -1;
  const double * I = inertia;
  h.model.inertias[static_cast<std::size_t>(joint) + 1] = pinocchio::Inertia(
    I[0], Eigen::Vector3d(I[1], I[2], I[3]),
    pinocchio::Symmetric3(I[4], I[5], I[6], I[7], I[8], I[9]));
  return 0;
}

// The terms of one sample into out (n + 4, n), row-major: rows 0..n-1 M(q) (symmetric), row
// n g(q), n+1 C(q,qd)·qd + g(q), n+2 the acceleration M(q)⁻¹·(total − C·qd − g) for the
// torque `total`, n+3 C(q,qd)^T·qd [SI]; only the rows `terms` (Terms) asks for are written.
// The acceleration is a Cholesky solve with CRBA's M and nonLinearEffects' nle (ABA when M
// is not positive definite numerically); Cᵀ·qd is ct_qd_of's.
void hofto_dyn1_terms(
  void * handle,
  std::int64_t terms,
  const double * q,
  const double * qd,
  const double * total,
  double * out)
{
  Handle & h = *static_cast<Handle *>(handle);
  try
  {
    terms_of(h, terms, q, qd, total, out);
  }
  catch (const std::exception &) // pinocchio's argument checks: not with these sizes
  {
    std::fill(out, out + (h.n + 4) * h.n, std::numeric_limits<double>::quiet_NaN());
  }
}

// RNEA: out (n) = M(q)·qdd + C(q,qd)·qd + g(q) [N m].
void hofto_dyn1_rnea(
  void * handle, const double * q, const double * qd, const double * qdd, double * out)
{
  Handle & h = *static_cast<Handle *>(handle);
  const Eigen::Index n = h.n;
  try
  {
    pinocchio::rnea(h.model, h.data, In(q, n), In(qd, n), In(qdd, n));
    Eigen::Map<Eigen::VectorXd>(out, n) = h.data.tau;
  }
  catch (const std::exception &)
  {
    std::fill(out, out + n, std::numeric_limits<double>::quiet_NaN());
  }
}

} // extern "C"
