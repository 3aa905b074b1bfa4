# build/dist/ipmsm_fmu-<version>-py3-none-any.whl: the scenarios package with its data, the three
# FMUs as FMI 2.0 and as FMI 3.0 (Linux and, with IPMSM_WIN64, Windows binaries) and the SSP
# package (tools/wheel/make_wheel.py; setuptools, pyproject.toml). Target `wheel`, part of ALL
# (./test.sh and ./run.sh's set-up build it) except in the sanitizer build, whose FMUs are not for
# shipping.
set(IPMSM_WHEEL ${CMAKE_BINARY_DIR}/dist/ipmsm_fmu-${PROJECT_VERSION}-py3-none-any.whl)
file(GLOB_RECURSE IPMSM_WHEEL_SOURCES CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/scenarios/*)
list(FILTER IPMSM_WHEEL_SOURCES EXCLUDE REGEX "/__pycache__/")
add_custom_command(
  OUTPUT ${IPMSM_WHEEL}
  COMMAND ${Python3_EXECUTABLE} ${PROJECT_SOURCE_DIR}/tools/wheel/make_wheel.py ${CMAKE_BINARY_DIR}
          ${CMAKE_BINARY_DIR}/dist
  DEPENDS ${CMAKE_BINARY_DIR}/fmu/IpmsmController.fmu ${CMAKE_BINARY_DIR}/fmu/IpmsmPlant.fmu
          ${CMAKE_BINARY_DIR}/fmu/IpmsmDrive.fmu ${CMAKE_BINARY_DIR}/fmu3/IpmsmController.fmu
          ${CMAKE_BINARY_DIR}/fmu3/IpmsmPlant.fmu ${CMAKE_BINARY_DIR}/fmu3/IpmsmDrive.fmu
          ${CMAKE_BINARY_DIR}/ssp/IpmsmControllerPlant.ssp
          ${PROJECT_SOURCE_DIR}/tools/wheel/make_wheel.py ${PROJECT_SOURCE_DIR}/pyproject.toml
          ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/CHANGELOG.md
          ${PROJECT_SOURCE_DIR}/fmu_src/resources/ev_ipmsm_default.csv
          ${PROJECT_SOURCE_DIR}/fmu_src/coupling/ipmsm_drive.coupling
          ${PROJECT_SOURCE_DIR}/docs/motor/efficiency_map.json ${IPMSM_WHEEL_SOURCES}
  COMMENT "Building the wheel ${IPMSM_WHEEL}"
  VERBATIM)
if(IPMSM_SANITIZE)
  add_custom_target(wheel DEPENDS ${IPMSM_WHEEL})
else()
  add_custom_target(wheel ALL DEPENDS ${IPMSM_WHEEL})
endif()
add_dependencies(wheel IpmsmController_fmu IpmsmPlant_fmu IpmsmDrive_fmu IpmsmController_fmi3_fmu IpmsmPlant_fmi3_fmu
                 IpmsmDrive_fmi3_fmu IpmsmControllerPlant_ssp)
