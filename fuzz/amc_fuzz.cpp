// AMC reader, against a fixed skeleton: any bytes give a motion or a located
// error; a motion it gives converts to GMR and can be viewed.
#include "fuzz_util.h"
#include "gmr/acclaim/amc.h"
#include "gmr/acclaim/asf.h"
#include "gmr/acclaim/convert.h"

namespace {

// Every kind of dof: root translation and rotation, 3, 2 and 1 rotation
// dofs, a length dof, a bone without dofs.
constexpr std::string_view kAsf = R"(:version 1.10
:name fuzz
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name hip
     direction 0.34202 -0.939693 0
     length 7.5
     axis 0 0 20 XYZ
     dof rx ry rz
  end
  begin
     id 2
     name knee
     direction 0.34202 -0.939693 0
     length 7.0
     axis 0 0 20 XYZ
     dof rx l
  end
  begin
     id 3
     name back
     direction 0 1 0
     length 2
     axis 0 0 0 XYZ
     dof rz rx
  end
  begin
     id 4
     name tip
     direction 0 1 0
     length 1
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root hip back
    hip knee
    back tip
  end
)";

const gmr::AsfSkeleton& skeleton() {
  static const gmr::AsfSkeleton s = gmr::parse_asf(kAsf, "fuzz.asf").value();
  return s;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto amc = gmr::parse_amc(text, "fuzz.amc", skeleton(), &warnings);
  if (!amc.ok()) return 0;
  auto m = gmr::acclaim_to_gmr(skeleton(), *amc);
  if (m.ok()) gmr::fuzz::exercise(*m);
  return 0;
}
