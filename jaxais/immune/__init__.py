"""The paper's immune network and its learning (SPEC 3-8): ``antigens``, ``antibodies`` (Table
1), ``behaviours``, ``reinforcement`` (Table 2), ``network`` (eqs 1-10) and ``readings`` (our
readings of its open points). Pure functions of arrays and keys; no task loop, no simulator."""
