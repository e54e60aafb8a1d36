#include "io/json.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

namespace lockstep::json {
namespace {

TEST(CliJson, ParsesEveryKindOfValue) {
  const Value v = parse(R"( {"a": [1, -2.5e3, 0], "b": {"c": true, "d": false, "e": null}, "s": "x\"\\\n\u00e9"} )");
  ASSERT_TRUE(v.is_object());
  ASSERT_EQ(v.object.size(), 3u);
  EXPECT_EQ(v.object[0].first, "a");  // file order kept
  const Value* a = v.find("a");
  ASSERT_TRUE(a && a->is_array());
  ASSERT_EQ(a->array.size(), 3u);
  EXPECT_EQ(a->array[1].number, -2500.0);
  const Value* b = v.find("b");
  ASSERT_TRUE(b && b->is_object());
  EXPECT_EQ(b->find("c")->type, Value::Type::Bool);
  EXPECT_TRUE(b->find("c")->boolean);
  EXPECT_EQ(b->find("e")->type, Value::Type::Null);
  EXPECT_EQ(v.find("s")->string, "x\"\\\n\xc3\xa9");
  EXPECT_EQ(v.find("missing"), nullptr);
}

TEST(CliJson, ReadsNonFiniteTokensSoCallersCanNameTheKey) {
  const Value v = parse("[NaN, Infinity, -Infinity, 1e999]");
  EXPECT_TRUE(std::isnan(v.array[0].number));
  EXPECT_EQ(v.array[1].number, std::numeric_limits<double>::infinity());
  EXPECT_EQ(v.array[2].number, -std::numeric_limits<double>::infinity());
  EXPECT_TRUE(std::isinf(v.array[3].number));
}

TEST(CliJson, RejectsMalformedInputWithLineAndColumn) {
  for (const char* bad : {"", "{", "[1,]", "{\"a\" 1}", "{\"a\": 1,}", "01", "1.", "1e", "+1", ".5", "tru",
                          "\"unterminated", "\"tab\there\"", "\"\\x\"", "[1] 2", "{\"a\": 1, \"a\": 2}",
                          "\"\\ud800\"", "{1: 2}"}) {
    EXPECT_THROW(parse(bad), ParseError) << bad;
  }
  try {
    parse("{\n  \"a\": [1,\n  2,,]\n}", "state.json");
    FAIL() << "no error";
  } catch (const ParseError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("state.json:3:5: ", 0), 0u) << e.what();
  }
  try {
    parse(R"({"q": 1, "q": 2})", "s.json");
    FAIL() << "no error";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("duplicate key \"q\""), std::string::npos) << e.what();
  }
  try {
    parse(R"({"q": {"knee": 01}})", "s.json");
    FAIL() << "no error";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("s.json:1:17: invalid number: JSON numbers have no leading zeros"),
              std::string::npos)
        << e.what();
  }
}

TEST(CliJson, RejectsRunawayNesting) {
  EXPECT_THROW(parse(std::string(100000, '[')), ParseError);
}

TEST(CliJson, MissingFileIsAParseErrorNamingIt) {
  try {
    parse_file("/nonexistent/state.json");
    FAIL() << "no error";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/state.json"), std::string::npos);
  }
}

// A directory opens as a stream that reads nothing: it was reported as
// "1:1: unexpected end of input".
TEST(CliJson, DirectoryIsAParseErrorSayingSo) {
  const std::string dir = ::testing::TempDir() + "lockstep_json_dir.json";
  std::filesystem::create_directories(dir);
  try {
    parse_file(dir);
    FAIL() << "no error";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find(dir + ": is a directory"), std::string::npos) << e.what();
  }
  std::filesystem::remove(dir);
}

TEST(CliJson, NumbersRoundTripAndNonFiniteBecomesNull) {
  for (const double x : {0.0, -0.0, 1.0, 0.1, -2.5e-300, 1.7976931348623157e308, 3.141592653589793}) {
    const std::string text = number(x);
    EXPECT_EQ(parse(text).number, x) << text;
  }
  EXPECT_EQ(number(0.1), "0.1");
  EXPECT_EQ(number(std::numeric_limits<double>::quiet_NaN()), "null");
  EXPECT_EQ(number(std::numeric_limits<double>::infinity()), "null");
}

TEST(CliJson, QuotedStringsReadBack) {
  const std::string s = "a\"b\\c\nd\te\x01";
  EXPECT_EQ(quote("plain"), "\"plain\"");
  EXPECT_EQ(parse(quote(s)).string, s);
}

}  // namespace
}  // namespace lockstep::json
