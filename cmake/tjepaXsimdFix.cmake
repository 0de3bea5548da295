# Debian bookworm's xsimd 8.1 exports its target with INTERFACE_LINK_LIBRARIES "xtl", but the
# package neither depends on xtl nor needs it (xtl is only for XSIMD_ENABLE_XTL_COMPLEX, which tjepa
# does not use). Without a target of that name the linker sees "-lxtl" and fails, so we provide an
# empty one when nobody else has.
if(TARGET xsimd AND NOT TARGET xtl)
  add_library(xtl INTERFACE IMPORTED)
endif()
