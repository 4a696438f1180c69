// Looking mode of `lumigraph view` (issue 18 part B): lists the artifacts and
// draws each with its controls. Filled in on branch viewlook.
"use strict";
