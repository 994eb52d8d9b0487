# CMake package of the dyfos C API, installed by client/ffi/install.sh as
# PREFIX/lib/cmake/dyfos/dyfosConfig.cmake. Use:
#
#   find_package(dyfos REQUIRED)          # with -DCMAKE_PREFIX_PATH=PREFIX
#   target_link_libraries(app PRIVATE dyfos::dyfos)          # libdyfos.so
#   target_link_libraries(app PRIVATE dyfos::dyfos_static)   # libdyfos.a
#
# Both targets carry the include directory (dyfos.h, dyfos.hpp).
get_filename_component(_dyfos_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
if(NOT TARGET dyfos::dyfos)
  add_library(dyfos::dyfos SHARED IMPORTED)
  set_target_properties(dyfos::dyfos PROPERTIES
    IMPORTED_LOCATION "${_dyfos_prefix}/lib/libdyfos.so"
    INTERFACE_INCLUDE_DIRECTORIES "${_dyfos_prefix}/include")
  add_library(dyfos::dyfos_static STATIC IMPORTED)
  set_target_properties(dyfos::dyfos_static PROPERTIES
    IMPORTED_LOCATION "${_dyfos_prefix}/lib/libdyfos.a"
    INTERFACE_INCLUDE_DIRECTORIES "${_dyfos_prefix}/include"
    INTERFACE_LINK_LIBRARIES "gcc_s;util;rt;pthread;m;dl")
endif()
set(dyfos_FOUND TRUE)
unset(_dyfos_prefix)
