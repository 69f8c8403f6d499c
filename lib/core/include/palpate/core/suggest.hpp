#pragma once
/// @file
/// "Did you mean": the programs' answer to a mistyped flag (`--poisson 0.45`
/// gets "did you mean --poisson-ratio?" rather than only "not expected").

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace palpate {

/// The known flag closest to @p typed ("--poisson"), as "--poisson-ratio";
/// "" when none is close. Close: one is a prefix of the other (at least
/// three letters shared), or their edit distance is at most a third of
/// the longer one. @p known: long names without dashes.
std::string closest_flag(std::string_view typed, std::span<const std::string> known);

/// " (did you mean --x?)" for the arguments of @p args that start with "--",
/// are not known and have a close known flag (each suggestion once); ""
/// otherwise. `--name=value` is read as `--name`.
std::string flag_suggestions(std::span<const std::string> args, std::span<const std::string> known);

/// The long flag names of a CLI11 application and of its subcommands,
/// without dashes (a template so that this header needs no CLI11).
template <typename App>
std::vector<std::string> long_flag_names(const App& app) {
  std::vector<std::string> names;
  for (const auto* option : app.get_options())
    for (const auto& name : option->get_lnames()) names.push_back(name);
  for (const auto* sub : app.get_subcommands([](const auto*) { return true; }))
    for (auto& name : long_flag_names(*sub)) names.push_back(std::move(name));
  return names;
}

}  // namespace palpate
