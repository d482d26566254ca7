"""Running a mission's components across hosts: the controller's proxies (`remote`) and the devices' gates seen
from the controller (`gates`). The daemon (`drd.daemon`) serves them; the interpreter sees only components."""
