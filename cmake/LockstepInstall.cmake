# `cmake --install`: the library, its headers under include/lockstep (folder
# structure kept: layout/, kernels/, batch/, io/), the `lockstep` program,
# the bundled models under share/lockstep/models, and a CMake package so that
# another project can find_package(lockstep) and link lockstep::lockstep.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(LOCKSTEP_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/lockstep)
set(LOCKSTEP_INSTALL_MODELSDIR ${CMAKE_INSTALL_DATADIR}/lockstep/models)

# lockstep_flags (warnings only) is linked privately by the static library
# and so must be exported with it; consumers get none of its flags.
install(TARGETS lockstep lockstep_flags lockstep_cpu_check
  EXPORT lockstepTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  OBJECTS DESTINATION ${CMAKE_INSTALL_LIBDIR}/lockstep/objects)
install(TARGETS lockstep_tool RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

# io/rollout_hdf5.hpp is internal to the library (it includes hdf5.h).
foreach(_dir layout kernels batch io)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${_dir}/
    DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/lockstep/${_dir}
    FILES_MATCHING PATTERN "*.hpp" PATTERN "rollout_hdf5.hpp" EXCLUDE)
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/tools/cpu_check.hpp DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/lockstep/tools)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/models/ DESTINATION ${LOCKSTEP_INSTALL_MODELSDIR})

install(EXPORT lockstepTargets NAMESPACE lockstep:: DESTINATION ${LOCKSTEP_INSTALL_CMAKEDIR})
string(REPLACE ";" " " LOCKSTEP_PUBLIC_FLAGS_TEXT "${LOCKSTEP_PUBLIC_FLAGS}")
# The HDF5 library the static lockstep links, named in lockstepConfig.cmake.
get_target_property(LOCKSTEP_HDF5_LIBRARY hdf5::hdf5 IMPORTED_LOCATION)
if(NOT LOCKSTEP_HDF5_LIBRARY)
  message(FATAL_ERROR "FindHDF5 gave hdf5::hdf5 no IMPORTED_LOCATION: cannot name it in lockstepConfig.cmake")
endif()
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/lockstepConfig.cmake.in
  ${PROJECT_BINARY_DIR}/lockstepConfig.cmake
  INSTALL_DESTINATION ${LOCKSTEP_INSTALL_CMAKEDIR}
  PATH_VARS LOCKSTEP_INSTALL_MODELSDIR)
# 0.x: minor versions may break the API.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/lockstepConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/lockstepConfig.cmake ${PROJECT_BINARY_DIR}/lockstepConfigVersion.cmake
  DESTINATION ${LOCKSTEP_INSTALL_CMAKEDIR})
