#pragma once
// Private to palpate_runtime: the one way a solver explains a refused
// request or a failed solve, without allocating (the request path and the
// tool tick are allocation-free).

#include <fmt/format.h>

#include <array>
#include <utility>

#include "palpate/runtime/request_status.hpp"

namespace palpate::detail {

/// Writes the explanation into @p message (cut to its size, never
/// allocating) and returns @p status.
template <typename... Args>
RequestStatus fail(std::array<char, 256>& message, RequestStatus status,
                   fmt::format_string<Args...> format, Args&&... args) {
  const auto end =
      fmt::format_to_n(message.data(), message.size() - 1, format, std::forward<Args>(args)...);
  *end.out = '\0';
  return status;
}

}  // namespace palpate::detail
