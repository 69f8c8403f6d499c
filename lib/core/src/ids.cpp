#include "palpate/core/ids.hpp"

namespace palpate {

bool is_valid_id(std::string_view id) {
  if (id.empty() || id.size() > 63) return false;
  for (const char c : id) {
    const bool letter_or_digit =
        (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
    if (!letter_or_digit && c != '_' && c != '-' && c != '.') return false;
  }
  return true;
}

}  // namespace palpate
