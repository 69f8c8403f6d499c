#include "palpate/core/suggest.hpp"

#include <algorithm>
#include <numeric>

namespace palpate {

namespace {

/// Levenshtein distance: insertions, deletions and substitutions.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  std::iota(row.begin(), row.end(), std::size_t{0});
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string_view without_dashes(std::string_view flag) {
  while (!flag.empty() && flag.front() == '-') flag.remove_prefix(1);
  return flag.substr(0, flag.find('='));
}

}  // namespace

std::string closest_flag(std::string_view typed, std::span<const std::string> known) {
  const std::string_view name = without_dashes(typed);
  if (name.size() < 2) return {};
  std::string best;
  std::size_t best_score = SIZE_MAX;
  for (const std::string& candidate : known) {
    if (candidate == name) return {};  // known after all
    const std::string_view shorter = name.size() < candidate.size() ? name : candidate;
    const std::string_view longer = name.size() < candidate.size() ? candidate : name;
    std::size_t score = SIZE_MAX;
    if (shorter.size() >= 3 && longer.substr(0, shorter.size()) == shorter)
      score = longer.size() - shorter.size();  // a prefix: closer the less is missing
    else if (const std::size_t d = edit_distance(name, candidate); 3 * d <= longer.size())
      score = d;
    if (score < best_score) {
      best_score = score;
      best = "--" + candidate;
    }
  }
  return best;
}

std::string flag_suggestions(std::span<const std::string> args,
                             std::span<const std::string> known) {
  std::vector<std::string> said;
  for (const std::string& arg : args) {
    if (arg.size() < 3 || arg.rfind("--", 0) != 0) continue;
    std::string flag = closest_flag(arg, known);
    if (flag.empty() || std::find(said.begin(), said.end(), flag) != said.end()) continue;
    said.push_back(std::move(flag));
  }
  if (said.empty()) return {};
  std::string text = " (did you mean ";
  for (std::size_t i = 0; i < said.size(); ++i)
    text += (i == 0 ? "" : i + 1 == said.size() ? " or " : ", ") + said[i];
  return text + "?)";
}

}  // namespace palpate
