#pragma once
// The single source of tjepa's version: CMakeLists.txt reads these three lines.
#define TJEPA_VERSION_MAJOR 0
#define TJEPA_VERSION_MINOR 1
#define TJEPA_VERSION_PATCH 0

#define TJEPA_DETAIL_STR2(x) #x
#define TJEPA_DETAIL_STR(x) TJEPA_DETAIL_STR2(x)
#define TJEPA_VERSION_STRING                                                                       \
  TJEPA_DETAIL_STR(TJEPA_VERSION_MAJOR)                                                            \
  "." TJEPA_DETAIL_STR(TJEPA_VERSION_MINOR) "." TJEPA_DETAIL_STR(TJEPA_VERSION_PATCH)

namespace tjepa {
inline constexpr int version_major = TJEPA_VERSION_MAJOR;
inline constexpr int version_minor = TJEPA_VERSION_MINOR;
inline constexpr int version_patch = TJEPA_VERSION_PATCH;
inline constexpr const char* version_string = TJEPA_VERSION_STRING;
}  // namespace tjepa
