// The tick's rigid-body dynamics as plain C functions: pinocchio's own algorithms (CRBA, ABA,
// Coriolis matrix, gravity, nonlinear effects, RNEA) on a copy of the robot's pinocchio model,
// called from numba kernels (hofto_hw/model/kernels.py) so that a snapshot or a feed-forward is
// one Python->compiled call. Built and loaded by hofto_hw/model/native/build.py.
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
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <cstdint>
#include <algorithm>
#include <exception>
#include <limits>
#include <stdexcept>
#include <string>

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
    explicit Handle(const Model & m)
    : model(m)
    , data(model)
    , n(model.nv)
    {
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
    if (terms & ACCEL)
    {
      pinocchio::aba(h.model, h.data, Q, V, In(total, n));
      Eigen::Map<Eigen::VectorXd>(row + 2 * n, n) = h.data.ddq;
    }
    if (terms & MASS)
    {
      pinocchio::crba(h.model, h.data, Q);
      const Eigen::MatrixXd & M = h.data.M; // the upper triangle is CRBA's
      for (Eigen::Index i = 0; i < n; ++i)
        for (Eigen::Index k = 0; k < n; ++k)
          out[i * n + k] = k >= i ? M(i, k) : M(k, i);
    }
    if (terms & CORIOLIS_T)
    {
      pinocchio::computeCoriolisMatrix(h.model, h.data, Q, V);
      const Eigen::MatrixXd & C = h.data.C;
      for (Eigen::Index i = 0; i < n; ++i)
      {
        double acc = 0.0;
        for (Eigen::Index k = 0; k < n; ++k)
          acc += C(k, i) * qd[k];
        row[3 * n + i] = acc;
      }
    }
    if (terms & GRAVITY)
    {
      pinocchio::computeGeneralizedGravity(h.model, h.data, Q);
      Eigen::Map<Eigen::VectorXd>(row, n) = h.data.g;
    }
    if (terms & NLE)
    {
      pinocchio::nonLinearEffects(h.model, h.data, Q, V);
      Eigen::Map<Eigen::VectorXd>(row + n, n) = h.data.nle;
    }
  }
} // namespace hofto_native

using namespace hofto_native;

extern "C" {

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

std::int64_t hofto_dyn1_dof(void * handle)
{
  return static_cast<Handle *>(handle)->n;
}

// The terms of one sample into out (n + 4, n), row-major: rows 0..n-1 M(q) (symmetric), row
// n g(q), n+1 C(q,qd)·qd + g(q), n+2 the ABA acceleration for the torque `total`, n+3
// C(q,qd)^T·qd [SI]; only the rows `terms` (Terms) asks for are written, in the order ABA,
// CRBA, Coriolis matrix, gravity, nonlinear effects (that of the Python path).
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
