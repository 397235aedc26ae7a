/* The FMI 3.0 variables of a native FMU over its model's variables (fmu_model.h): FMI 3 value reference v is entry v
 * of the table, an array variable (X [K,3], T [L], ...) or a scalar standing for `count` consecutive model value
 * references from `first`, row-major, as fmu_src/linknet_fmu/layout.py numbers them; value reference 0 is the
 * independent variable time. The table is scene data, written by fmu_src/native/build_fmi3.py into the FMU's resource
 * file (fmu_resource.h) as the entries fmi3.n_variables, fmi3.names (texts), fmi3.kind (int32), fmi3.first and
 * fmi3.count (int64); the glue (fmi3Functions.c) reads it at instantiation and knows no physics.
 */
#ifndef LINKNET_FMI3_VARIABLES_H
#define LINKNET_FMI3_VARIABLES_H

enum fmi3_variable_kind { FMI3_TIME = 0, FMI3_FLOAT64 = 1, FMI3_STRING = 2, FMI3_BOOLEAN = 3 };

typedef struct fmi3_variable {
    const char *name;
    unsigned kind;      /* enum fmi3_variable_kind */
    unsigned first;     /* the model's value reference of element 1 */
    unsigned count;     /* elements (1 for a scalar) */
} fmi3_variable;

#endif
