// SHA-256 (file/hash.hpp) against the published test vectors (FIPS 180-2).
#include "palpate/file/hash.hpp"

#include <gtest/gtest.h>

#include <string>

namespace palpate {
namespace {

TEST(Sha256, KnownVectors) {
  Sha256 empty;
  EXPECT_EQ(empty.hex_digest(),
            "sha256:e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  Sha256 abc;
  abc.update("abc");
  EXPECT_EQ(abc.hex_digest(),
            "sha256:ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

TEST(Sha256, IncrementalEqualsWhole) {
  const std::string text = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
  Sha256 whole, parts;
  whole.update(text);
  parts.update(text.substr(0, 13));
  parts.update(text.data() + 13, text.size() - 13);
  const std::string digest = whole.hex_digest();
  EXPECT_EQ(digest, parts.hex_digest());
  EXPECT_EQ(digest, "sha256:248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

}  // namespace
}  // namespace palpate
