"""The electromechanical actuator around the PRSM FMU: motor, controller, load, co-simulation master (to come)."""
