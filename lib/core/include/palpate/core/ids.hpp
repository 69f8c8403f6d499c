#pragma once
/// @file
/// The one rule for the names palpate's programs exchange: model, daemon,
/// client and tool ids.

#include <string_view>

namespace palpate {

/// 1 to 63 characters among A-Z a-z 0-9 _ - . : the rule for model, daemon,
/// client and tool ids (a client id also names its reply partition, so it
/// never holds a partition wildcard).
bool is_valid_id(std::string_view id);

}  // namespace palpate
