// Placeholder: implemented by the core issue.
#include "core/triangle_distance.h"
