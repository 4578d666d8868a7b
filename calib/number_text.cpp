#include "calib/number_text.h"

#include <cctype>
#include <cmath>
#include <cstdlib>

namespace omni {
namespace {

bool IsDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

// At most this many characters of a bad token are quoted in a message.
constexpr size_t kQuotedLength = 40;

std::string Quoted(const std::string& token) {
  return "\"" + (token.size() > kQuotedLength ? token.substr(0, kQuotedLength) + "..." : token) +
         "\"";
}

}  // namespace

bool IsDecimalNumber(std::string_view token) {
  size_t i = 0;
  if (i < token.size() && (token[i] == '-' || token[i] == '+')) ++i;
  size_t digits = 0;
  bool point = false;
  for (; i < token.size(); ++i) {
    if (IsDigit(token[i])) {
      ++digits;
    } else if (token[i] == '.' && !point) {
      point = true;
    } else {
      break;
    }
  }
  if (digits == 0) return false;
  if (i < token.size() && (token[i] == 'e' || token[i] == 'E')) {
    ++i;
    if (i < token.size() && (token[i] == '-' || token[i] == '+')) ++i;
    size_t exponent_digits = 0;
    for (; i < token.size() && IsDigit(token[i]); ++i) ++exponent_digits;
    if (exponent_digits == 0) return false;
  }
  return i == token.size();
}

bool IsDecimalInteger(std::string_view token) {
  size_t i = 0;
  if (i < token.size() && (token[i] == '-' || token[i] == '+')) ++i;
  if (i == token.size()) return false;
  for (; i < token.size(); ++i) {
    if (!IsDigit(token[i])) return false;
  }
  return true;
}

bool ParseDecimal(const std::string& token, double* value) {
  if (!IsDecimalNumber(token)) return false;
  const double parsed = std::strtod(token.c_str(), nullptr);
  if (!std::isfinite(parsed)) return false;
  *value = parsed;
  return true;
}

std::string DecimalProblem(const std::string& token) {
  if (!IsDecimalNumber(token)) return "expected a decimal number, got " + Quoted(token);
  return "number out of range (too large for a double): " + Quoted(token);
}

}  // namespace omni
