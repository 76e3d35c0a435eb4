"""Reference controllers for HydroHIL: genuine external CAN clients of ``hydrohil serve``.

One idea per module:

* :mod:`.plant`        the plant-client interface (:class:`~.plant.Observation`, :class:`~.plant.PlantClient`)
* :mod:`.plant_can`    the plant over CAN (python-can socketcand client + the shipped DBC), lockstep or realtime
* :mod:`.plant_local`  the same interface on the in-process simulator (``sim_core``), no CAN ("simulated")
* :mod:`.valve_model`  the identified valve characteristic (deadband, amplifier, spool, opening polynomial) and its inverse
* :mod:`.feedforward`  the valve-model feedforward of Papadopoulos et al. (2003), eqs. (19)-(21)
* :mod:`.pid`          the joint PID of Fig. 10 (filtered derivative of the measured angle, conditioned integrator,
                       deadband compensation, settle band)
* :mod:`.kinematics`   harvester forward/inverse kinematics of the end point (``stick_tip``)
* :mod:`.trajectories` reference trajectories (sinusoid, operator Cartesian velocity profile, target sequences)
* :mod:`.tracking`     PID (+ feedforward) on every joint, and the generic control loop that records a trace
* :mod:`.scenarios`    the closed-loop experiments (stick, cartesian, mars_nd): controllers and their metrics
* :mod:`.client`       the controller process (``python -m controllers.client``): runs one scenario over CAN
* :mod:`.server`       starting ``hydrohil serve`` subprocesses on free ports
* :mod:`.experiment`   one reproduction: emulator + controller process, the in-process comparison runs, metrics
* :mod:`.plots`        the figures
* :mod:`.cli`          ``hydrohil reproduce``
"""
