"""Contact: obstacles and bodies that touch (the [contact] and [[obstacle]] tables of a scene).

    base.py       the [contact] settings, which solver takes which method, what IPC and penalty share
    build.py      build_contact(model): the scene's contact, or None
    scene.py      parsing [contact] and [[obstacle]]
    obstacles.py  rigid, kinematic obstacles: analytic shapes and triangle meshes, their motion
    surface.py    the body's contact surface, taken from its mesh
    ipc.py        Incremental Potential Contact through the IPC Toolkit (barrier, CCD, friction)
    penalty.py    a quadratic penalty on penetration (explicit runs too)
"""
