// Tokens files (plain and hashed, errors naming the line), role permissions, new tokens, login
// sessions that expire and end with their token.
#include "idms/server/auth.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <thread>

#include "child_process.h"

namespace idms::server {
namespace {

TEST(TokenTable, ParsesPlainAndHashedTokensWithComments) {
  const std::string plain = "admin-token-0123456789";
  const std::string hashed = "observer-token-0123456789";
  // sha256("observer-token-0123456789") computed by DigestOf, written as hex.
  const Digest d = DigestOf(hashed);
  std::string hex;
  for (uint8_t b : d) {
    static constexpr char k[] = "0123456789abcdef";
    hex += k[b >> 4];
    hex += k[b & 15];
  }
  TokenTable t;
  std::string error;
  ASSERT_TRUE(TokenTable::Parse("# comment\n\nadmin " + plain + "  # trailing\nobserver sha256:" + hex + "\n", "tok",
                                &t, &error))
      << error;
  EXPECT_EQ(t.size(), 2u);
  EXPECT_EQ(t.Lookup(plain), Role::kAdmin);
  EXPECT_EQ(t.Lookup(hashed), Role::kObserver);
  EXPECT_EQ(t.Lookup("admin-token-012345678"), Role::kNone);
  EXPECT_EQ(t.Lookup(""), Role::kNone);
}

TEST(TokenTable, BadLinesAreErrorsNamingTheLine) {
  TokenTable t;
  std::string error;
  EXPECT_FALSE(TokenTable::Parse("admin aaaaaaaaaaaaaaaaaaaa\nroot bbbbbbbbbbbbbbbbbbbbbb\n", "tokens", &t, &error));
  EXPECT_EQ(error, "tokens:2: unknown role 'root' (expected admin, agent or observer)");
  EXPECT_FALSE(TokenTable::Parse("\n\nagent sha256:abc\n", "tokens", &t, &error));
  EXPECT_EQ(error, "tokens:3: expected 64 hex digits after 'sha256:'");
  EXPECT_FALSE(TokenTable::Parse("agent a b\n", "tokens", &t, &error));
  EXPECT_NE(error.find("tokens:1:"), std::string::npos);
  EXPECT_FALSE(TokenTable::Parse("agent short\n", "tokens", &t, &error));
  EXPECT_NE(error.find("at least 16"), std::string::npos);
  // The table passed in is untouched by a failed parse.
  TokenTable good;
  ASSERT_TRUE(TokenTable::Parse("agent aaaaaaaaaaaaaaaaaaaa\n", "t", &good, &error));
  EXPECT_FALSE(TokenTable::Parse("nope\n", "t", &good, &error));
  EXPECT_EQ(good.Lookup("aaaaaaaaaaaaaaaaaaaa"), Role::kAgent);
}

TEST(Roles, PermissionsFollowTheIssue) {
  EXPECT_TRUE(Allows(Role::kObserver, Permission::kRead));
  EXPECT_FALSE(Allows(Role::kObserver, Permission::kPublish));
  EXPECT_FALSE(Allows(Role::kObserver, Permission::kWrite));
  EXPECT_TRUE(Allows(Role::kAgent, Permission::kRead));
  EXPECT_TRUE(Allows(Role::kAgent, Permission::kPublish));
  EXPECT_FALSE(Allows(Role::kAgent, Permission::kWrite));
  EXPECT_TRUE(Allows(Role::kAdmin, Permission::kWrite));
  EXPECT_FALSE(Allows(Role::kNone, Permission::kRead));
}

TEST(Tokens, NewTokensAreRandomAndAppendedHashedToA0600File) {
  const std::string a = NewToken(), b = NewToken();
  EXPECT_EQ(a.size(), 43u);
  EXPECT_NE(a, b);
  const std::string path = test::TempDir("tokens") + "/tokens";
  std::string error;
  const std::string t1 = AppendNewToken(path, Role::kAgent, &error);
  const std::string t2 = AppendNewToken(path, Role::kAdmin, &error);
  ASSERT_FALSE(t1.empty()) << error;
  struct stat st {};
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const std::string text = test::ReadText(path);
  EXPECT_EQ(text.find(t1), std::string::npos);  // only the hash is stored
  TokenTable table;
  ASSERT_TRUE(TokenTable::Load(path, &table, &error)) << error;
  EXPECT_EQ(table.Lookup(t1), Role::kAgent);
  EXPECT_EQ(table.Lookup(t2), Role::kAdmin);
}

TEST(Tokens, DefaultFileHasOneTokenPerRole) {
  const std::string path = test::TempDir("default-tokens") + "/tokens";
  std::string error;
  ASSERT_TRUE(CreateDefaultTokens(path, &error)) << error;
  TokenTable table;
  ASSERT_TRUE(TokenTable::Load(path, &table, &error)) << error;
  EXPECT_EQ(table.size(), 3u);
  struct stat st {};
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
}

// MemoryLoginSessions: the store contract (pg_store_test.cc, Stores/Sqlite) checks it.

}  // namespace
}  // namespace idms::server
