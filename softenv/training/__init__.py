"""The trainee wing: a person (or a recorded device) at the laryngoscope, and how well they did.

* :mod:`.logs` -- device logs: the hand-pose and force-command schemas, files and their checks.
* :mod:`.hand` -- the hand-log vocabulary: a log's scene, poses, workspace and speed limits.
* :mod:`.trainee` -- the scripted expert's hand log and synthetic trainees (graded errors of technique).
* :mod:`.scoring` -- replay a log through its scene and score it against the expert (``softenv score``).
* :mod:`.profiles` -- trainee profiles built to published clinical measurements, to check the score against.
* :mod:`.identify` -- the tongue's and the coupling's stiffness fitted to a recorded session by gradients (torch).
* :mod:`.play` -- a person at the keyboard and mouse, or a haptic device over the bridge (``softenv play``; the
  ``play`` extra).
* :mod:`.bridge` -- the UDP bridge a haptic device's driver process drives a session through (poses in, force out).
"""
