# Makes the OpenCV modules Reflex needs available as GLOBAL targets named like OpenCV's own
# (opencv_core, opencv_imgproc, ...), so that vision/ and tests/vision/ can both link them.
# Debian's OpenCVConfig.cmake ships only in the libopencv-dev meta package; the per-module
# -dev packages (libopencv-core-dev, ...) are enough here: without the config we find the
# headers and libraries directly.
set(_reflex_cv_modules core imgproc imgcodecs videoio calib3d aruco)
find_package(OpenCV 4 QUIET CONFIG)
if(OpenCV_FOUND)
  foreach(_t IN LISTS OpenCV_LIBS)
    if(TARGET ${_t})
      get_target_property(_imported ${_t} IMPORTED)
      get_target_property(_global ${_t} IMPORTED_GLOBAL)
      if(_imported AND NOT _global)
        set_target_properties(${_t} PROPERTIES IMPORTED_GLOBAL TRUE)
      endif()
    endif()
  endforeach()
  message(STATUS "reflex vision: OpenCV ${OpenCV_VERSION} from its CMake config")
else()
  find_path(REFLEX_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
  foreach(_m IN LISTS _reflex_cv_modules)
    find_library(REFLEX_OPENCV_${_m}_LIBRARY opencv_${_m} REQUIRED)
    if(NOT TARGET opencv_${_m})
      add_library(opencv_${_m} SHARED IMPORTED GLOBAL)
      set_target_properties(opencv_${_m} PROPERTIES
        IMPORTED_LOCATION ${REFLEX_OPENCV_${_m}_LIBRARY}
        INTERFACE_INCLUDE_DIRECTORIES ${REFLEX_OPENCV_INCLUDE_DIR})
    endif()
  endforeach()
  message(STATUS "reflex vision: OpenCV from ${REFLEX_OPENCV_INCLUDE_DIR} (no OpenCVConfig.cmake; "
                 "install libopencv-dev to use it)")
endif()
