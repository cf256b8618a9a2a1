// The one name rule for names that cross a process boundary, and the escape
// every printer applies to another program's text.
#include "gmr/core/names.h"

#include <gtest/gtest.h>

#include <string>

namespace gmr {
namespace {

TEST(Names, OrdinaryNamesInAnyScriptPass) {
  for (const std::string name : {"walk", "cmu/02_01", "LeftUpLeg", "mixamorig:Hips", "CC_Base_L_Thigh", "Bip01 Spine",
                                 "h\xC3\xBC"
                                 "fte",
                                 "\xE8\x85\xB0", "\xF0\x9F\x8F\x83 runner", "a\\b"}) {
    EXPECT_EQ(name_problem(name), "") << name;
  }
}

TEST(Names, ControlInvisibleBidiAndLookAlikeSpacesAreRefusedWithWhereAndWhat) {
  struct Case {
    std::string name, expected;
  };
  for (const Case& c : std::initializer_list<Case>{
           {"", "the name is empty"},
           {std::string(201, 'a'), "a name of 201 bytes; at most 200"},
           {" walk", "starts or ends with a space"},
           {"walk ", "starts or ends with a space"},
           {"walk\x1b[31m", "control character (U+001B, byte 4)"},
           {"a\nb", "control character (U+000A, byte 1)"},
           {"a\tb", "control character (U+0009, byte 1)"},
           {"a\x7f", "control character (U+007F, byte 1)"},
           {"a\xC2\x85", "control character (U+0085, byte 1)"},            // NEL (C1)
           {"walk\xE2\x80\x8B", "look-alike character (U+200B, byte 4)"},  // zero-width space
           {"\xE2\x80\xAEklaw", "look-alike character (U+202E, byte 0)"},  // right-to-left override
           {"a\xE2\x81\xA6"
            "b",
            "look-alike character (U+2066, byte 1)"},  // left-to-right isolate
           {"a\xC2\xA0"
            "b",
            "look-alike character (U+00A0, byte 1)"},  // no-break space
           {"a\xE3\x80\x80"
            "b",
            "look-alike character (U+3000, byte 1)"},                        // ideographic space
           {"\xEF\xBB\xBFwalk", "look-alike character (U+FEFF, byte 0)"},    // byte-order mark
           {"a\xF3\xA0\x80\x81", "look-alike character (U+E0001, byte 1)"},  // a tag character
           {"a\xC3", "not UTF-8 (byte 1)"},
           {"a\xC0\xAF", "not UTF-8 (byte 1)"},          // an overlong '/'
           {"a\xED\xA0\x80", "not UTF-8 (byte 1)"},      // a surrogate
           {"a\xF4\x90\x80\x80", "not UTF-8 (byte 1)"},  // past U+10FFFF
       }) {
    const std::string why = name_problem(c.name);
    EXPECT_NE(why.find(c.expected), std::string::npos) << "'" << c.name << "': " << why;
  }
}

TEST(Names, TerminalSafeEscapesWhatNameProblemRefusesAndKeepsTheRest) {
  EXPECT_EQ(terminal_safe("walk"), "walk");
  EXPECT_EQ(terminal_safe("h\xC3\xBC"
                          "fte \xE8\x85\xB0"),
            "h\xC3\xBC"
            "fte \xE8\x85\xB0");
  EXPECT_EQ(terminal_safe("Hips\x1b[31m\x07"), "Hips\\x1b[31m\\x07");
  EXPECT_EQ(terminal_safe("a\nb\tc\rd"), "a\\nb\\tc\\x0dd");
  EXPECT_EQ(terminal_safe("walk\xE2\x80\x8B"), "walk\\u{200b}");
  EXPECT_EQ(terminal_safe("\xE2\x80\xAEklaw"), "\\u{202e}klaw");
  EXPECT_EQ(terminal_safe("a\xC2\x9B"
                          "2J"),
            "a\\u{9b}2J");  // CSI as a C1 character
  EXPECT_EQ(terminal_safe("a\xC3"), "a\\xc3");
  EXPECT_EQ(terminal_safe("a\xFF\xFE"
                          "b"),
            "a\\xff\\xfeb");
  // Whatever the input, the output holds no control byte and is valid UTF-8.
  std::string every_byte;
  for (int b = 0; b < 256; ++b) every_byte += static_cast<char>(b);
  const std::string safe = terminal_safe(every_byte);
  for (const char c : safe) {
    const auto u = static_cast<unsigned char>(c);
    EXPECT_FALSE(u < 0x20 || u == 0x7f) << static_cast<int>(u);
  }
  EXPECT_EQ(name_problem(safe, safe.size()), "");
}

}  // namespace
}  // namespace gmr
