#pragma once
// Numbers in the text files omnisculpt reads (TUM trajectories, ascii PLY, frames.csv, COLMAP
// text models): plain decimal notation only. strtod alone would also take hexadecimal ("0x10"),
// "inf", "nan" and a number too large for a double (as infinity); these are bad input.

#include <string>
#include <string_view>

namespace omni {

// An optional sign, digits with at most one '.', an optional exponent ("e-3"); nothing else.
bool IsDecimalNumber(std::string_view token);
// An optional sign and digits.
bool IsDecimalInteger(std::string_view token);

// The whole token as a finite double: false unless IsDecimalNumber(token) and the value fits a
// double (1e309 does not).
bool ParseDecimal(const std::string& token, double* value);

// The problem with a token that ParseDecimal refused, for an error message: "expected a decimal
// number, got \"0x10\"" or "number out of range (too large for a double): \"1e309\"".
std::string DecimalProblem(const std::string& token);

}  // namespace omni
