"""operator: the operator's side of the link.

Modules (import them directly):

* ``pilots``: who or what moves the sticks — the :class:`~testbed.operator.pilots.Pilot`
  protocol every new pilot plugs into, and the packaged scripted, attitude and supervisor
  pilots.
* ``station``: the operator's own ECS world, which samples the pilot once per operator frame
  and writes the intents the link carries.
* ``live_pilot``: the pilot a person flies from the browser console (``testbed live``).
* ``video``: the operator's image console (progressive ROI images).
"""
