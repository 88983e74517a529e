"""The robots the fleet must show whether they speak or not: the inventory file's, and those heard before.

`file` reads the operator's inventory, `reload` keeps the fleet following the file as it changes,
`registry` keeps the robots heard on disk so that a restart forgets none, `memory` writes them there as
the fleet hears them, and `retirement` forgets a robot on purpose, recording who did.
"""
