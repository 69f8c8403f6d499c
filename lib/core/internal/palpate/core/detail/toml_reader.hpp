#pragma once
// Private to the library: typed access to a parsed TOML file whose every
// failure names the file, the line, the key and what is accepted.

#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <filesystem>
#include <initializer_list>
#include <string>
#include <string_view>

#include "palpate/core/eigen.hpp"
#include "palpate/core/error.hpp"

namespace palpate::detail {

class TomlReader {
 public:
  explicit TomlReader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const toml::node* node, const std::string& key,
                         const std::string& what) const {
    const auto line = node ? node->source().begin.line : 0;
    throw InputError(line ? fmt::format("{}:{}: {}: {}", file_, line, key, what)
                          : fmt::format("{}: {}: {}", file_, key, what));
  }

  void only_keys(const toml::table& table, const std::string& where,
                 std::initializer_list<std::string_view> allowed) const {
    for (const auto& [key, node] : table) {
      if (std::find(allowed.begin(), allowed.end(), key.str()) == allowed.end()) {
        std::string list;
        for (auto a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        fail(&node, where.empty() ? std::string(key.str()) : where + "." + std::string(key.str()),
             fmt::format("unknown key (accepted here: {})", list));
      }
    }
  }

  double number(const toml::node& node, const std::string& key) const {
    if (auto v = node.value<double>()) return *v;
    fail(&node, key, "expected a number");
  }
  bool boolean(const toml::node& node, const std::string& key) const {
    if (auto v = node.value_exact<bool>()) return *v;
    fail(&node, key, "expected true or false");
  }
  std::string string(const toml::node& node, const std::string& key) const {
    if (auto v = node.value<std::string>()) return *v;
    fail(&node, key, "expected a string");
  }
  Eigen::Vector3d vec3(const toml::node& node, const std::string& key) const {
    const auto* arr = node.as_array();
    if (!arr || arr->size() != 3) fail(&node, key, "expected an array of 3 numbers [x, y, z]");
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = number((*arr)[static_cast<size_t>(i)], key);
    return v;
  }
  const toml::table& table(const toml::node& node, const std::string& key) const {
    if (const auto* t = node.as_table()) return *t;
    fail(&node, key, "expected a table");
  }
  template <typename F>
  void each_table(const toml::node& node, const std::string& key, F f) const {
    const auto* arr = node.as_array();
    if (!arr) fail(&node, key, "expected an array of tables");
    for (const auto& item : *arr) f(table(item, key));
  }

 private:
  std::string file_;
};

inline std::filesystem::path relative_to(const std::filesystem::path& base, const std::string& p) {
  std::filesystem::path path(p);
  return (path.is_absolute() ? path : base / path).lexically_normal();
}

/// Reads @p file as TOML. @throws InputError with the line and column of a syntax error.
toml::table parse_toml_file(const std::filesystem::path& file);

}  // namespace palpate::detail
