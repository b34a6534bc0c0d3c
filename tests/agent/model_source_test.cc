// The model cache's content hash (SHA-256 against the FIPS 180-4 vectors) and library names.
#include "idms/agent/model_source.h"

#include <gtest/gtest.h>

namespace idms::test {
namespace {

TEST(ModelSource, Sha256StandardVectors) {
  EXPECT_EQ(agent::Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(agent::Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(agent::Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(agent::Sha256Hex(std::string(1000000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(ModelSource, NamesAndVersions) {
  std::string name, version, error;
  ASSERT_TRUE(agent::ParseModelName("hex_4x5_home@12", &name, &version, &error));
  EXPECT_EQ(name, "hex_4x5_home");
  EXPECT_EQ(version, "12");
  ASSERT_TRUE(agent::ParseModelName("liver-v2.1", &name, &version, &error));
  EXPECT_EQ(version, "");
  for (const char* bad : {"", "../etc/passwd", "a/b", "x@", "x@1a", "we ird", "a..b"}) {
    EXPECT_FALSE(agent::ParseModelName(bad, &name, &version, &error)) << bad;
    EXPECT_NE(error.find("NAME@VERSION"), std::string::npos);
  }
}

}  // namespace
}  // namespace idms::test
