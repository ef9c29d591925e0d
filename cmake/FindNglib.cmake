# SPDX-License-Identifier: MIT
# Finds Netgen's nglib as packaged by Debian (libnglib-dev): /usr/include/netgen/nglib.h and
# /usr/lib/<triplet>/netgen/libnglib.so. nglib.h must be included inside `namespace nglib { }`.
# Defines Nglib::Nglib.
find_path(Nglib_INCLUDE_DIR nglib.h PATH_SUFFIXES netgen)
find_library(Nglib_LIBRARY NAMES nglib PATH_SUFFIXES netgen)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Nglib REQUIRED_VARS Nglib_LIBRARY Nglib_INCLUDE_DIR)
if(Nglib_FOUND AND NOT TARGET Nglib::Nglib)
  get_filename_component(_ng_dir "${Nglib_LIBRARY}" DIRECTORY)
  add_library(Nglib::Nglib UNKNOWN IMPORTED)
  set_target_properties(Nglib::Nglib PROPERTIES
    IMPORTED_LOCATION "${Nglib_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${Nglib_INCLUDE_DIR}"
    INTERFACE_LINK_DIRECTORIES "${_ng_dir}")
endif()
mark_as_advanced(Nglib_INCLUDE_DIR Nglib_LIBRARY)
