"""Shared by the backend tests."""

# A free box with a position-controlled arm on a hinge, above a floor.
ARM_ON_BOX_XML = """
<mujoco><option timestep="0.005" integrator="implicitfast"/>
<worldbody><geom type="plane" size="5 5 .1"/>
<body name="base" pos="0 0 0.5"><freejoint/><geom type="box" size=".1 .1 .1" mass="1"/>
 <body name="arm" pos="0.2 0 0"><joint name="hinge" axis="0 1 0" range="-2 2"/>
  <geom type="capsule" size=".02" fromto="0 0 0 .3 0 0" mass=".3"/></body></body>
</worldbody>
<actuator><position joint="hinge" kp="50" kv="2"/></actuator>
<sensor><framepos objtype="xbody" objname="arm"/><contact subtree1="base" data="found" reduce="netforce" num="1"/></sensor>
</mujoco>"""
