// insnav/core.hpp -- umbrella header of the insnav header-only core.
#pragma once

#include "insnav/check.hpp"
#include "insnav/earth/wgs84.hpp"
#include "insnav/ins/mechanization.hpp"
#include "insnav/ins/nav_state.hpp"
#include "insnav/math/rotation.hpp"
