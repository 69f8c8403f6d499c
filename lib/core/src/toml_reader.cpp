#include "palpate/core/detail/toml_reader.hpp"

namespace palpate::detail {

toml::table parse_toml_file(const std::filesystem::path& file) {
  try {
    return toml::parse_file(file.string());
  } catch (const toml::parse_error& e) {
    if (!std::filesystem::exists(file))
      throw InputError(fmt::format("{}: no such file", file.string()));
    throw InputError(fmt::format("{}:{}:{}: not valid TOML: {}", file.string(),
                                 e.source().begin.line, e.source().begin.column, e.description()));
  }
}

}  // namespace palpate::detail
