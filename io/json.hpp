// A small strict JSON reader and the few writing helpers the CLI needs.
//
// Reading follows RFC 8259 (objects, arrays, strings with escapes, numbers,
// true/false/null; nothing after the value but white space) with two
// deliberate differences: duplicate object keys are an error, and the tokens
// NaN, Infinity and -Infinity are read as numbers so that a caller can reject
// a non-finite value by naming its key rather than by a syntax error.
#pragma once

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace lockstep::json {

// Syntax errors; the message gives the source, line and column.
class ParseError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Value {
  enum class Type { Null, Bool, Number, String, Array, Object };
  Type type = Type::Null;
  bool boolean = false;
  double number = 0.0;
  std::string string;
  std::vector<Value> array;
  std::vector<std::pair<std::string, Value>> object;  // in file order, keys unique

  bool is_number() const { return type == Type::Number; }
  bool is_array() const { return type == Type::Array; }
  bool is_object() const { return type == Type::Object; }
  // The member named `key`, or nullptr (objects only).
  const Value* find(const std::string& key) const;
};

const char* type_name(Value::Type type);  // "null", "boolean", "number", ...

// `source` names the text in error messages (a file name, or "<string>").
Value parse(const std::string& text, const std::string& source = "<string>");
// Reads and parses a file; a file that cannot be read is a ParseError too.
Value parse_file(const std::string& path);

// Writing: a number in the shortest form that reads back to the same double
// (non-finite numbers, which JSON cannot hold, become null), and a quoted,
// escaped string.
std::string number(double x);
std::string quote(const std::string& s);

}  // namespace lockstep::json
