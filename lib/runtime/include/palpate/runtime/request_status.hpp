#pragma once
/// @file
/// What a request asks of a vertex, and how a request ends: the vocabulary
/// the constraint solver, the wire module and every client share
/// (docs/dds.md, "Status codes"). Numbers match idl/palpate.idl.

#include <cstdint>

namespace palpate {

/// What a request asks of one vertex (numbers match idl/palpate.idl).
enum class ConstraintKind : std::int32_t {
  kForce = 0,               ///< value = applied force, N
  kDisplacement = 1,        ///< value = imposed displacement, m
  kNormalDisplacement = 2,  ///< value[0] = displacement along the normal, m; no tangential force
};

/// Outcome of a request (numbers match ReplyStatus in idl/palpate.idl and
/// the table in docs/dds.md).
enum class RequestStatus : std::int32_t {
  kOk = 0,
  kUnknownModel,
  kVertexOutOfRange,
  kVertexNotOnSurface,
  kVertexFixed,
  kDuplicateVertex,
  kNonFiniteValue,
  kBadConstraint,
  kTooManyConstraints,
  kIllConditioned,
  kInternalError,
  kDisplacementTooLarge,  ///< longer than the model's bound (SolverLimits::max_displacement_m)
  kForceTooLarge,         ///< larger than the bound (SolverLimits::max_force_n)
};

/// Stable lower-case name of a status ("vertex_fixed"), for logs and docs.
const char* status_name(RequestStatus status);

}  // namespace palpate
