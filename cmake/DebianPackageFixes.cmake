# Repairs for two faults in Debian 12 (bookworm) CMake package files, so that the
# imported targets can be used as they are. See ../shared/REFERENCE.md, "CMake targets
# and two packaging faults".
#
# 1. OpenImageIO::OpenImageIO lists /usr/include/opencv4 among its include directories
#    whether or not OpenCV is installed; CMake's generate step then fails with
#    "includes non-existent path". We drop every listed directory that does not exist.
# 2. OpenColorIO's config sits flat in /usr/share/cmake (not on the default search path)
#    and exports the include directory "/include" (its _IMPORT_PREFIX is computed one
#    level too high). We search there and point the target at the real include dir.

# Remove include directories that do not exist from an imported target.
function(bokeh_drop_missing_include_dirs target)
  get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
  if(NOT dirs)
    return()
  endif()
  set(kept "")
  foreach(d IN LISTS dirs)
    if(EXISTS "${d}")
      list(APPEND kept "${d}")
    endif()
  endforeach()
  set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${kept}")
endfunction()

find_package(OpenImageIO CONFIG REQUIRED)
bokeh_drop_missing_include_dirs(OpenImageIO::OpenImageIO)
bokeh_drop_missing_include_dirs(OpenImageIO::OpenImageIO_Util)

find_package(OpenColorIO CONFIG REQUIRED PATHS /usr/share/cmake)
if(TARGET OpenColorIO::OpenColorIO)
  find_path(BOKEH_OCIO_INCLUDE_DIR OpenColorIO/OpenColorIO.h REQUIRED)
  bokeh_drop_missing_include_dirs(OpenColorIO::OpenColorIO)
  set_property(TARGET OpenColorIO::OpenColorIO APPEND PROPERTY
               INTERFACE_INCLUDE_DIRECTORIES "${BOKEH_OCIO_INCLUDE_DIR}")
endif()
