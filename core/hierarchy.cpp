// Placeholder: implemented by the core issue.
#include "core/hierarchy.h"
