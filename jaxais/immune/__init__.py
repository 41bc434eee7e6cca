"""The paper's immune network and its learning (Whitbrook, Aickelin & Garibaldi, SPEC 3-8).

Modules: ``antigens`` (what the robot senses, as one of eight antigens), ``antibodies`` (Table 1:
an antibody's behaviour and its attributes), ``behaviours`` (the wheel speeds of each behaviour),
``reinforcement`` (Table 2: the RL score and the penalties), ``network`` (Farmer's model, eqs
1-10: paratopes, idiotopes, selection), ``readings`` (our readings of the paper's open points, one
frozen dataclass). Pure functions of arrays and PRNG keys; nothing here knows about the task loop
or the simulator.
"""
