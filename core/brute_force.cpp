// Placeholder: implemented by the core issue.
#include "core/brute_force.h"
