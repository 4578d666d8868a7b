#include "calib/number_text.h"

#include <gtest/gtest.h>

#include <string>

namespace omni {
namespace {

TEST(NumberText, DecimalNumbersOnly) {
  for (const char* token : {"0", "-1", "+2", "3.", ".5", "-0.25", "1e3", "1E-3", "2.5e+10"}) {
    EXPECT_TRUE(IsDecimalNumber(token)) << token;
  }
  // strtod reads all of these but none is a decimal number.
  for (const char* token :
       {"",    "+",      "-",        ".",     "e3",    "1e",  "1e+", "0x10", "0X1p3", "inf", "-inf",
        "nan", "NaN(1)", "infinity", "1.2.3", "1e3.5", "--1", " 1",  "1 ",   "1,5",   "١"}) {
    EXPECT_FALSE(IsDecimalNumber(token)) << token;
  }
  EXPECT_TRUE(IsDecimalInteger("-12"));
  EXPECT_TRUE(IsDecimalInteger("+0"));
  for (const char* token : {"", "-", "1.0", "1e2", "0x1", " 1"}) {
    EXPECT_FALSE(IsDecimalInteger(token)) << token;
  }
}

TEST(NumberText, ParseDecimalRefusesWhatDoesNotFitADouble) {
  double value = -1.0;
  EXPECT_TRUE(ParseDecimal("1.5e300", &value));
  EXPECT_EQ(value, 1.5e300);
  EXPECT_TRUE(ParseDecimal("1e-400", &value));  // underflows to 0: representable, kept
  EXPECT_EQ(value, 0.0);
  value = 7.0;
  EXPECT_FALSE(ParseDecimal("1e309", &value));
  EXPECT_FALSE(ParseDecimal(std::string(400, '9'), &value));
  EXPECT_FALSE(ParseDecimal("0x10", &value));
  EXPECT_EQ(value, 7.0);  // untouched on failure
  EXPECT_EQ(DecimalProblem("0x10"), "expected a decimal number, got \"0x10\"");
  EXPECT_EQ(DecimalProblem("-1e999"), "number out of range (too large for a double): \"-1e999\"");
  EXPECT_EQ(DecimalProblem(std::string(50, 'a')),
            "expected a decimal number, got \"" + std::string(40, 'a') + "...\"");
}

}  // namespace
}  // namespace omni
