#pragma once
/// @file
/// SHA-256 of a problem's inputs, so files and shards can tell whether they
/// come from the same inputs.

#include <string>
#include <string_view>

namespace palpate {

/// Incremental SHA-256 (OpenSSL).
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  void update(const void* data, size_t bytes);
  void update(std::string_view text) { update(text.data(), text.size()); }
  /// "sha256:" followed by 64 lowercase hex digits. Ends the hash.
  std::string hex_digest();

 private:
  void* ctx_;
};

}  // namespace palpate
