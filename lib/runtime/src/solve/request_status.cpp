#include "palpate/runtime/request_status.hpp"

namespace palpate {

const char* status_name(RequestStatus status) {
  switch (status) {
    case RequestStatus::kOk:
      return "ok";
    case RequestStatus::kUnknownModel:
      return "unknown_model";
    case RequestStatus::kVertexOutOfRange:
      return "vertex_out_of_range";
    case RequestStatus::kVertexNotOnSurface:
      return "vertex_not_on_surface";
    case RequestStatus::kVertexFixed:
      return "vertex_fixed";
    case RequestStatus::kDuplicateVertex:
      return "duplicate_vertex";
    case RequestStatus::kNonFiniteValue:
      return "non_finite_value";
    case RequestStatus::kBadConstraint:
      return "bad_constraint";
    case RequestStatus::kTooManyConstraints:
      return "too_many_constraints";
    case RequestStatus::kIllConditioned:
      return "ill_conditioned";
    case RequestStatus::kInternalError:
      return "internal_error";
    case RequestStatus::kDisplacementTooLarge:
      return "displacement_too_large";
    case RequestStatus::kForceTooLarge:
      return "force_too_large";
  }
  return "unknown_status";
}

}  // namespace palpate
